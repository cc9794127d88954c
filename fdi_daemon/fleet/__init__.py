"""Replaying a fleet's recordings: many files, each with its rig's model, on Dask.

- `replay_one`: one recording -> its summary (the code path of `fdi replay` too) and row;
- `inputs`: which recordings (a folder or a glob) and which model for each (a model map);
- `cluster`: the rows of many recordings, computed on a Dask cluster;
- `table`: the rows as CSV or Parquet.
"""
