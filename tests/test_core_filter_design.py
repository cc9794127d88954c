"""core/filter_design.butter gives scipy.signal.butter's coefficients to the last bit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from fdi_daemon.core.filter_design import butter


@pytest.mark.parametrize("btype", ["low", "high"])
@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 8])
def test_butter_equals_scipy_bit_for_bit(order, btype):
    for fs in (100.0, 256.0, 1000.0):
        for cutoff in (0.05, 0.5, 1.0, 2.0, 7.3, 0.45 * fs):
            b, a = butter(order, cutoff, fs, btype)
            b_ref, a_ref = scipy.signal.butter(order, cutoff, btype=btype, fs=fs)
            assert b.dtype == b_ref.dtype and a.dtype == a_ref.dtype
            np.testing.assert_array_equal(b, b_ref)
            np.testing.assert_array_equal(a, a_ref)


@pytest.mark.parametrize("cutoff", [0.0, -1.0, 128.0, 200.0])
def test_butter_refuses_a_cutoff_outside_nyquist(cutoff):
    with pytest.raises(ValueError, match="critical frequencies"):
        butter(2, cutoff, 256.0)


def test_butter_refuses_other_band_types_and_orders():
    with pytest.raises(ValueError, match="btype"):
        butter(2, 1.0, 256.0, "band")
    with pytest.raises(ValueError, match="order"):
        butter(-1, 1.0, 256.0)
