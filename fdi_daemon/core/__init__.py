"""Pure numerics, no I/O: IIR blocks, velocity estimator, window least squares, statistics."""
