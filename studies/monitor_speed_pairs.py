"""`Monitor.run` against the compiled reference chain, per sample, for two versions of the
code alternating (docs/detector.md §6: steadier than one `fdi bench` run on a shared
machine). Run: ``python studies/monitor_speed_pairs.py TREE_A TREE_B [ROUNDS]``, each TREE a
checkout (``git worktree add /tmp/a <rev>``); prints, per round and tree, the best of five
runs over 1 M samples: ns a sample of the monitor and of the chain, and their ratio.
"""

import os
import subprocess
import sys

_ONE = r"""
import time, numpy as np
from fdi_daemon.bench.monitor import _system, FS_HZ
from fdi_daemon.bench.reference_chain import ReferenceChain
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.recordings import Recording
model, vb, ab = _system()
N = 1_000_000
reps = -(-N // vb.size)
v, a = np.tile(vb, reps)[:N], np.tile(ab, reps)[:N]
rec = Recording({"t": np.arange(N) / FS_HZ, "v_in": v, "accel": a}, {"fs": str(FS_HZ)})
window = Monitor(model).detector.window_samples
Monitor(model).run(rec)
ReferenceChain.from_model(model, window).run(v, a)
mon, ref = [], []
for _ in range(5):
    m = Monitor(model)
    c0 = time.process_time(); m.run(rec, trace_every=N); c1 = time.process_time()
    ReferenceChain.from_model(model, window).run(v, a); c2 = time.process_time()
    mon.append((c1 - c0) / N * 1e9); ref.append((c2 - c1) / N * 1e9)
print(f"monitor {min(mon):.0f} ns, chain {min(ref):.1f} ns, ratio {min(ref) / min(mon):.3f}")
"""


def main() -> None:
    trees = [t for t in sys.argv[1:] if not t.isdigit()]
    rounds = int(next((t for t in sys.argv[1:] if t.isdigit()), "3"))
    for _ in range(rounds):
        for tree in trees:
            env = dict(os.environ, PYTHONPATH=os.path.abspath(tree))
            out = subprocess.run(
                [sys.executable, "-c", _ONE],
                env=env,
                cwd=tree,
                capture_output=True,
                text=True,
                check=True,
            ).stdout
            print(f"{tree}: {out.strip()}", flush=True)


if __name__ == "__main__":
    main()
