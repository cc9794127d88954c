"""The θ history of the status snapshot (`detect.history.History`) against a
`collections.deque` with the same bound, the way the monitor held it before."""

from collections import deque

import numpy as np
import pytest

from fdi_daemon.detect.history import History


@pytest.mark.parametrize("size", [1, 5, 300])
def test_history_keeps_the_newest_points_in_order_like_a_bounded_deque(size):
    rng = np.random.default_rng(size)
    history, reference = History(size), deque(maxlen=size)
    for _ in range(300):
        if rng.random() < 0.5:  # one tick (`Monitor.step`)
            point = tuple(rng.random(3))
            history.append(*point)
            reference.append(point)
        else:  # a chunk's points (`Monitor.run`), as strided views
            count = int(rng.integers(0, 2 * size + 3))
            t, theta1, theta2 = rng.random((3, 2 * count))[:, ::2]
            history.extend(t, theta1, theta2)
            reference.extend(zip(t, theta1, theta2))
        assert np.array_equal(history.points(), np.array(list(reference)).reshape(-1, 3))
