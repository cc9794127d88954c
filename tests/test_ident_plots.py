"""Identification figures: a legible phase, a validation zoom, the signature's RMS view with
honest labels and units, legends off the data."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np
from conftest_ident import FS, plant
from scipy import signal

from fdi_daemon.ident.plots import (
    identification_figure,
    phase_on_model_branch,
    signature_figure,
    zoom_window,
)


def legends_off_the_data(fig) -> None:
    fig.canvas.draw()
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is not None:
            assert not legend.get_window_extent().overlaps(ax.get_window_extent()), ax.get_title()


def test_phase_of_noisy_data_stays_on_the_models_branch():
    rng = np.random.default_rng(0)
    f = np.linspace(0.1, 120, 800)
    b, a = plant()
    _, model = signal.freqz(b, a, worN=f, fs=FS)
    # beyond 30 Hz the estimate is noise: a random phase that unwraps to thousands of degrees
    G = model * np.where(f > 30, 5 * np.exp(1j * rng.uniform(-np.pi, np.pi, f.size)), 1.0)
    old = np.degrees(np.unwrap(np.angle(G)))
    assert np.ptp(old) > 1000  # what the figure showed before
    model_deg, data_deg = phase_on_model_branch(G, model)
    assert np.all(np.abs(data_deg - model_deg) <= 180 + 1e-9)
    in_band = f <= 30
    np.testing.assert_allclose(data_deg[in_band], model_deg[in_band], atol=1e-9)

    fr = SimpleNamespace(freq_hz=f, G=G, coherence=np.where(f > 30, 0.2, 0.99))
    t = np.arange(60 * 256) / 256
    y = np.sin(2 * np.pi * 8 * t)
    y_sim = y + np.where((t > 30) & (t < 30.5), 0.3, 0.0)
    fig = identification_figure(
        fr, model, (1.5, 20.0), {"t": t, "y": y, "y_sim": y_sim, "fit_percent": 90.0}
    )
    ax_mag, ax_ph, _, ax_all, ax_zoom = fig.axes
    low, high = ax_ph.get_ylim()
    assert high - low < np.ptp(model_deg) + 400  # the band's phase is not flattened
    x0, x1 = ax_zoom.get_lines()[0].get_xdata()[[0, -1]]
    assert x1 - x0 <= 0.5 and 29.5 < x0 < 30.5  # a few periods, where the misfit is
    zoom_legend = ax_zoom.get_legend()  # the zoom had none: which trace is which?
    assert [x.get_text() for x in zoom_legend.get_texts()] == [
        "measured",
        "simulated (fit 90.0 %)",
    ]
    legends_off_the_data(fig)


def test_zoom_window_is_where_the_error_is_largest():
    t = np.arange(1000) / 100.0
    error = np.where((t >= 6) & (t < 6.5), 1.0, 0.01)
    mask = zoom_window(t, error, 0.5)
    assert mask.sum() == 50 and t[mask][0] == 6.0


def test_signature_figure_labels_what_was_fitted_and_gives_gamma_a_unit():
    from fdi_daemon.commands.signature import _fitted_residual_label

    args = argparse.Namespace(reference_window="1:21", prefilter_hz=None, lowpass_hz=10.0)
    label = _fitted_residual_label(args)
    assert label == "residual r − fault-free reference, low-passed 10 Hz"
    assert (
        _fitted_residual_label(
            argparse.Namespace(reference_window=None, prefilter_hz=None, lowpass_hz=None)
        )
        == "residual r"
    )

    t = 10 + np.arange(20 * 256) / 256
    residual = np.sin(2 * np.pi * 6 * t)
    result = SimpleNamespace(
        fit=SimpleNamespace(y_sim=0.9 * residual),
        gamma_f=3.14,
        info={"fit_percent": 90.0},
        grid=np.linspace(0, 10, 11),
        interval=(2.4, 4.0),
        flat=False,
        status="identified",
        relative_cost=lambda: 1 + (np.linspace(0, 10, 11) - 3.14) ** 2 / 10,
    )
    fig = signature_figure(t, residual, result, residual_label=label)
    ax_t, ax_z, ax_g = fig.axes
    texts = [x.get_text() for ax in (ax_t, ax_z) for x in ax.get_legend().get_texts()]
    assert label in texts and "acceleration residual" not in " ".join(texts)
    assert "γ_f = 3.14 s/m" in " ".join(texts) and ax_g.get_xlabel() == "γ (s/m)"
    rms = ax_t.get_lines()[0].get_ydata()  # the whole window as an RMS, not a solid block
    np.testing.assert_allclose(rms[200:-200], np.sqrt(0.5), rtol=0.02)
    x0, x1 = ax_z.get_lines()[0].get_xdata()[[0, -1]]
    assert x1 - x0 <= 1.0
    legends_off_the_data(fig)
    # the first panel's legend sat below it, under its t axis's label: now above its axes
    assert ax_t.get_legend().get_window_extent().y0 >= ax_t.get_window_extent().y1
    assert fig.get_suptitle().startswith("Residual and filtered friction signal")
