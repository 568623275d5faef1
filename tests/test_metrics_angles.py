"""Junction angle measure (crackbake.metrics.angles) on junctions with known angles."""

from __future__ import annotations

import numpy as np
import pytest

from crackbake.metrics.angles import junction_angles, mean_junction_angle, relaxation_time
from crackbake.network import Crack, CrackNetwork


def star(angles_deg, centre=(0.5, 0.5), length=0.3, n=31, frame=None) -> CrackNetwork:
    """Cracks leaving one shared point at the given in-plane angles, in the plane of ``frame``'s
    first two rows."""
    frame = np.eye(3) if frame is None else frame
    cracks = []
    t = np.linspace(0.0, length, n)[:, None]
    for k, a in enumerate(np.radians(angles_deg)):
        d = np.cos(a) * frame[0] + np.sin(a) * frame[1]
        pts = np.asarray(centre + (0.0,) * (3 - len(centre)), float) + t * d
        cracks.append(Crack(id=k, points=pts, faces=np.zeros(n), time=np.zeros(n),
                            width=np.ones(n), depth=np.ones(n)))
    return CrackNetwork(cracks=cracks, mesh={})


@pytest.mark.parametrize(("arms", "largest"), [
    ((0, 180, 90), 180.0),      # a T: through-crack straight, stem square
    ((0, 120, 240), 120.0),     # a Y
    ((0, 150, 270), 150.0),     # between: angles 150, 120, 90
    ((10, 60, 170), 200.0),     # all three cracks on one side: the largest angle passes 180
])
def test_largest_angle_of_known_junctions(arms, largest):
    assert junction_angles(star(arms)) == pytest.approx([largest], abs=1e-6)


def test_tilted_plane_and_curved_arms_measure_the_same():
    q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    assert junction_angles(star((0, 120, 240), frame=q.T)) == pytest.approx([120.0], abs=1e-6)
    # Arms bending away beyond the measuring scale do not count.
    net = star((0, 180, 90))
    tail = net.cracks[0].points
    tail[6:, 1] += np.linspace(0.0, 0.2, 25)  # the through-crack bends after a fifth
    assert junction_angles(net, scale=0.05) == pytest.approx([180.0], abs=1e-6)
    assert junction_angles(net, scale=0.15)[0] > 200.0


def test_no_junction_gives_nan_and_crossings_are_not_junctions():
    assert np.isnan(mean_junction_angle(star((0, 180))))
    assert len(junction_angles(star((0, 90, 180, 270)))) == 0


def test_relaxation_time_of_an_exponential():
    n = np.arange(1, 11)
    assert relaxation_time(n, 120 + 60 * np.exp(-(n - 1) / 4.0)) == pytest.approx(4.0)
    assert relaxation_time(n, np.full(10, 170.0)) == np.inf
    assert np.isnan(relaxation_time([1], [170.0]))
