"""Speed of the monitor: per-tick ``Monitor.step`` and batch ``Monitor.run``, each against a
straightforward implementation measured in the same run.

Data: the paper's §V system (`hil_sim.msd`: mass-spring-damper behind a valve-like input
filter, accelerometer noise) driven by a 1–12 Hz multisine, with its exact models — Ĝ the
zero-order-hold discretisation of v_in -> ẍ, G_e that of the friction force -> ẍ — so the
monitor runs its normal, alarm-free path. The batch data repeat the simulated block.

Baseline ("straightforward"): the same chain of eqs. (1), (3), (15)–(17) written plainly —
one ``scipy.signal.lfilter`` call per filter per sample (with its ``zi``) and a fresh
``np.linalg.lstsq`` over the last N samples on every tick; its batch path is the same loop.
It computes θ only (no detector), so the ratios understate our advantage.

Reference ("compiled chain", `fdi_daemon.bench.reference_chain`): the same chain compiled
with numba, without checks or detector: what the arithmetic alone costs per tick (one call
from Python per sample) and over arrays. The monitor is held to ratios against it (issue 15):
per-tick p50 within 3×, batch at least 30 % of its throughput. Both are measured side by
side, so that a shared machine's slow spells (they last from milliseconds to seconds) fall on
both alike: per tick, the two take each sample in turn; in batch, they take blocks of the
data in turn (tens of milliseconds each), and the ratio is the median over five such passes.

Incident replay (`fdi_daemon.bench.incident`): the replay throughput of a recording with
friction creeping in, against a quiet one of the same length; at least half is the target.
"""

from __future__ import annotations

import time

import numpy as np

FS_HZ = 256.0
BLOCK_S = 20.0


def _system():
    """(model, v_in, accel) of the §V system with exact Ĝ and G_e."""
    from fdi_daemon.core.velocity import VelocityEstimator
    from fdi_daemon.io.model_file import FaultFilter, FdiModel
    from hil_sim.msd import MsdParams, MsdSimulator, friction_tf, multisine, nominal_tf

    params = MsdParams(accel_noise_width=0.02, fs_hz=FS_HZ)
    coulomb_n, viscous = 0.5, 2.0
    num, den = friction_tf(params)
    plant_b, plant_a = nominal_tf(params)
    model = FdiModel(
        fs=FS_HZ,
        plant_b=plant_b,
        plant_a=plant_a,
        fault_filter=FaultFilter(b=-coulomb_n * num, f=den, nk=0, gamma_f=viscous / coulomb_n),
        velocity=VelocityEstimator(FS_HZ).settings(),
    )
    u = multisine(BLOCK_S, FS_HZ, 1.0, 12.0, 0.7, seed=1, n_tones=6)
    out = MsdSimulator(params, seed=0).run(u)
    return model, out["v_in"], out["accel"]


class _Baseline:
    """Eqs. (1), (3), (15)–(17) the plain way: per-sample lfilter, per-tick lstsq."""

    def __init__(self, model, window_samples: int) -> None:
        from fdi_daemon.core.velocity import VelocityEstimator

        vel = VelocityEstimator.from_settings(model.velocity, model.fs)
        ff = model.fault_filter
        b_e = np.concatenate([np.zeros(ff.nk), ff.b])
        self.filters = [
            [np.asarray(model.plant_b), np.asarray(model.plant_a)],
            [vel.b, vel.a],
            [b_e, ff.f],
            [b_e, ff.f],
        ]
        self.zi = [np.zeros(max(len(b), len(a)) - 1) for b, a in self.filters]
        self.n = window_samples
        self.g1: list[float] = []
        self.g2: list[float] = []
        self.r: list[float] = []

    def _filter(self, i: int, x: float) -> float:
        from scipy.signal import lfilter

        b, a = self.filters[i]
        y, self.zi[i] = lfilter(b, a, [x], zi=self.zi[i])
        return float(y[0])

    def step(self, v_in: float, accel: float) -> tuple[float, float]:
        r = accel - self._filter(0, v_in)
        v = self._filter(1, accel)
        self.g1.append(self._filter(2, float(np.sign(v))))
        self.g2.append(self._filter(3, v))
        self.r.append(r)
        if len(self.r) > self.n:
            del self.g1[0], self.g2[0], self.r[0]
        if len(self.r) < self.n:
            return float("nan"), float("nan")
        theta = np.linalg.lstsq(
            np.column_stack([self.g1, self.g2]), np.asarray(self.r), rcond=None
        )[0]
        return float(theta[0]), float(theta[1])


def _tick_times_us(steps, v_in, accel, warmup: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Wall-clock and thread-CPU time (µs) of every tick after ``warmup``, for each of
    ``steps``; they take each sample in turn, so a shared machine's slow spells fall on all
    of them alike."""
    clock = time.perf_counter_ns
    cpu = time.thread_time_ns
    wall = np.empty((len(steps), len(v_in)))
    used = np.empty((len(steps), len(v_in)))
    for k in range(len(v_in)):
        for j, step in enumerate(steps):
            c0 = cpu()
            t0 = clock()
            step(k, v_in[k], accel[k])
            wall[j, k] = clock() - t0
            used[j, k] = cpu() - c0
    return [(wall[j, warmup:] / 1e3, used[j, warmup:] / 1e3) for j in range(len(steps))]


def _batch_pair(
    model, window: int, rec, v_in: np.ndarray, accel: np.ndarray
) -> tuple[np.ndarray, list]:
    """One pass over the batch data by a new monitor (``Monitor.run``) and a new reference
    chain, side by side (`bench.side_by_side`); returns (monitor wall s, monitor CPU s,
    reference wall s, reference CPU s) and the monitor's events."""
    from fdi_daemon.bench.reference_chain import ReferenceChain
    from fdi_daemon.bench.side_by_side import BLOCK, side_by_side
    from fdi_daemon.detect.monitor import Monitor

    monitor = Monitor(model)
    ref = ReferenceChain.from_model(model, window)
    events: list = []
    spent = side_by_side(
        [
            lambda part: events.extend(monitor.run(rec.samples(part), trace_every=BLOCK)[0]),
            lambda part: ref.run(v_in[part], accel[part]),
        ],
        len(v_in),
    )
    return spent.ravel(), events


def bench_monitor(
    step_samples: int = 20_000,
    batch_samples: int = 2_000_000,
    baseline_samples: int = 3_000,
    incident_s: float = 1800.0,
    batch_pairs: int = 5,
) -> dict:
    """Measure; returns a dict of numbers (see `fdi bench`). incident_s: length of the
    incident and quiet recordings (0: leave the incident replay out); batch_pairs: passes
    over the batch data, the monitor and the reference chain taking its blocks in turn
    (`_batch_pair`; the throughputs and their ratio are the medians over the passes). The
    per-tick figures of the monitor and the reference come from one loop that gives each
    sample to both in turn."""
    from fdi_daemon.bench.incident import bench_incident_replay
    from fdi_daemon.bench.reference_chain import ReferenceChain
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.recordings import Recording
    from fdi_daemon.io.sample import Sample

    warmup = 2 * int(FS_HZ)
    if step_samples <= warmup:
        raise ValueError(f"step_samples must exceed the {warmup} ticks of the warm-up")
    model, v_block, a_block = _system()
    reps = -(-max(step_samples, batch_samples) // v_block.size)
    v_all = np.tile(v_block, reps)
    a_all = np.tile(a_block, reps)
    t_all = np.arange(v_all.size) / FS_HZ

    window = Monitor(model).detector.window_samples
    rec = Recording(
        {"t": t_all[:batch_samples], "v_in": v_all[:batch_samples], "accel": a_all[:batch_samples]},
        {"fs": str(FS_HZ)},
    )
    Monitor(model).run(rec.samples(slice(0, 4 * warmup)))  # load the compiled kernels first
    ReferenceChain.from_model(model, window).run(v_all[: 4 * warmup], a_all[: 4 * warmup])
    monitor = Monitor(model)
    ref = ReferenceChain.from_model(model, window)
    vs, accs, ts = (
        v_all[:step_samples].tolist(),
        a_all[:step_samples].tolist(),
        t_all[:step_samples].tolist(),
    )
    (step_us, step_cpu_us), (ref_us, ref_cpu_us) = _tick_times_us(
        [lambda k, v, a: monitor.step(Sample(k, ts[k], v, a)), lambda k, v, a: ref.step(v, a)],
        vs,
        accs,
        warmup,
    )

    base = _Baseline(model, window)
    base_v = v_all[:baseline_samples].tolist()
    base_a = a_all[:baseline_samples].tolist()
    [(base_us, base_cpu_us)] = _tick_times_us(
        [lambda k, v, a: base.step(v, a)], base_v, base_a, min(warmup, baseline_samples // 2)
    )
    pairs = []  # (monitor wall s, monitor CPU s, reference wall s, reference CPU s)
    for _ in range(batch_pairs):
        spent, events = _batch_pair(
            model, window, rec, v_all[:batch_samples], a_all[:batch_samples]
        )
        pairs.append(spent)
    batch_s, batch_cpu_s, ref_s, ref_cpu_s = np.median(pairs, axis=0)
    shares = [p[3] / p[1] for p in pairs]
    incident = bench_incident_replay(incident_s) if incident_s > 0 else None

    base_rate = 1e6 / float(np.mean(base_us))
    rate = batch_samples / batch_s
    p50, p99, worst = (float(x) for x in np.percentile(step_us, [50, 99, 100]))
    b50, b99, bworst = (float(x) for x in np.percentile(base_us, [50, 99, 100]))
    return {
        "step_us": {"p50": p50, "p99": p99, "max": worst, "samples": int(step_us.size)},
        "step_cpu_us_p50": float(np.median(step_cpu_us)),
        "baseline_step_cpu_us_p50": float(np.median(base_cpu_us)),
        "batch_samples_per_s": rate,
        "batch_samples_per_cpu_s": batch_samples / batch_cpu_s,
        "batch_samples": int(batch_samples),
        "batch_alarm_episodes": sum(e["kind"] == "fault_detected" for e in events),
        "baseline_step_us": {"p50": b50, "p99": b99, "max": bworst, "samples": int(base_us.size)},
        "baseline_samples_per_s": base_rate,
        "step_speedup_p50": b50 / p50,
        "batch_speedup": rate / base_rate,
        "reference_step_us": {
            "p50": float(np.median(ref_us)),
            "p99": float(np.percentile(ref_us, 99)),
            "samples": int(ref_us.size),
        },
        "reference_step_cpu_us_p50": float(np.median(ref_cpu_us)),
        "reference_samples_per_s": batch_samples / ref_s,
        "reference_samples_per_cpu_s": batch_samples / ref_cpu_s,
        "step_cpu_over_reference": float(np.median(step_cpu_us)) / float(np.median(ref_cpu_us)),
        "batch_cpu_share_of_reference": float(np.median(shares)),
        "batch_cpu_share_by_pair": [round(float(x), 4) for x in shares],
        **(
            {
                "incident_replay_samples_per_s": incident["incident"]["samples_per_s"],
                "incident_replay_samples_per_cpu_s": incident["incident"]["samples_per_cpu_s"],
                "quiet_replay_samples_per_s": incident["quiet"]["samples_per_s"],
                "quiet_replay_samples_per_cpu_s": incident["quiet"]["samples_per_cpu_s"],
                "incident_over_quiet_cpu": incident["incident"]["samples_per_cpu_s"]
                / incident["quiet"]["samples_per_cpu_s"],
                "incident_replay": incident,
            }
            if incident
            else {}
        ),
        "tick_budget_us": 1e6 / FS_HZ,
        "targets": {
            "step_p50_us": 30.0,
            "batch_samples_per_s": 1_000_000.0,
            "step_cpu_over_reference_max": 3.0,
            "batch_cpu_share_of_reference_min": 0.3,
            "incident_over_quiet_cpu_min": 0.5,
        },
    }
