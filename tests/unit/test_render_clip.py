"""``render3d._clipped``: the close-ups' yarn lines cut to the box the view shows keep every
segment that reaches into that box (checked point by point along each segment) and drop the rest
far from it."""

import numpy as np

from preform.io.render3d import _clipped


def _segments(blocks):
    return {tuple(np.round(np.concatenate([b[i], b[i + 1]]), 12)) for b in blocks for i in range(len(b) - 1)}


def test_clipped_keeps_every_segment_that_enters_the_box():
    rng = np.random.default_rng(5)
    # helices around z (yarns on a cylinder), with uneven point spacing
    blocks = []
    for k in range(12):
        t = np.sort(rng.uniform(0, 1, 300))
        a = 2 * np.pi * (3 * t + k / 12)
        blocks.append(np.column_stack([0.05 * np.cos(a), 0.05 * np.sin(a), 0.6 * t]))
    centre = np.array([0.0, 0.0, 0.3])
    right, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    half_right, half_up = 0.06, 0.03
    out = _clipped(blocks, centre, right, up, half_right, half_up)
    kept = _segments(out)
    assert all(len(b) >= 2 for b in out)
    s = np.linspace(0.0, 1.0, 201)
    entering, far = 0, 0
    for b in blocks:
        for i in range(len(b) - 1):
            pts = b[i] + s[:, None] * (b[i + 1] - b[i]) - centre
            inside = (np.abs(pts @ right) <= half_right) & (np.abs(pts @ up) <= half_up)
            key = tuple(np.round(np.concatenate([b[i], b[i + 1]]), 12))
            if inside.any():
                entering += 1
                assert key in kept                       # every segment the view can show
            elif np.min(np.abs(pts @ right)) > half_right + 0.05 or np.min(np.abs(pts @ up)) > half_up + 0.05:
                far += 1
                assert key not in kept                   # none far outside it
    assert entering > 100 and far > 100
    assert len(kept) < sum(len(b) - 1 for b in blocks) / 2
