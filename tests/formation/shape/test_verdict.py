"""The pair check of a built pyramid (agent/core/formation/shape/verdict.py, NAO paper 5.1.1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.core.formation.params import D_E, PHI_E_DEG
from agent.core.formation.shape.verdict import R_D_MAX, R_PHI_MAX, check_pair

PHI_E = math.radians(PHI_E_DEG)


def test_a_perfect_pair_worked_by_hand() -> None:
    # axis north; the child stands 0.8 m behind its parent, 30° to the right of the axis:
    # parent − child = 0.8·(sin 30°, cos 30°) = (0.4, 0.6928)
    c = check_pair(
        2, 1, D_E * np.array([math.sin(PHI_E), math.cos(PHI_E)]), math.pi / 2, D_E, PHI_E
    )
    assert c.distance == pytest.approx(D_E)
    assert c.angle == pytest.approx(PHI_E)
    assert c.r_d == pytest.approx(0.0, abs=1e-12) and c.r_phi == pytest.approx(0.0, abs=1e-12)
    assert c.ok


def test_the_issue_s_bent_pair() -> None:
    # robot 2 placed 15° off: the angle to its parent is 13.8° instead of 30°: r_φ −54 %
    phi = math.radians(13.8)
    c = check_pair(2, 1, D_E * np.array([math.sin(phi), math.cos(phi)]), math.pi / 2, D_E, PHI_E)
    assert c.r_phi == pytest.approx(-0.54)
    assert not c.ok
    assert c.text() == "r_d +0.0%, r_φ -54.0% to parent 1"


def test_distance_alone_fails_a_pair() -> None:
    c = check_pair(3, 1, np.array([0.0, 1.0]), math.pi / 2, 1.0 - R_D_MAX - 0.01, 0.1)
    assert abs(c.r_d) > R_D_MAX and not c.ok


@given(
    st.floats(-math.pi, math.pi),
    st.floats(0.3, 2.0),
    st.floats(0.05, 1.5),
    st.floats(-math.pi, math.pi),
)
def test_turning_the_whole_picture_changes_nothing(
    rot: float, d: float, phi: float, axis: float
) -> None:
    off = d * np.array([math.cos(axis + phi), math.sin(axis + phi)])
    a = check_pair(2, 1, off, axis, D_E, PHI_E)
    c, s = math.cos(rot), math.sin(rot)
    b = check_pair(2, 1, np.array([[c, -s], [s, c]]) @ off, axis + rot, D_E, PHI_E)
    assert a.r_d == pytest.approx(b.r_d, abs=1e-9)
    assert a.r_phi == pytest.approx(b.r_phi, abs=1e-6)
    # a ratio on its bound may fall either side of it once turned (rounding)
    on_bound = abs(abs(a.r_phi) - R_PHI_MAX) < 1e-6 or abs(abs(a.r_d) - R_D_MAX) < 1e-9
    assert a.ok == b.ok or on_bound


@pytest.mark.parametrize(
    ("offset", "axis", "d_e", "phi_e", "match"),
    [
        ([math.nan, 0.0], 0.0, D_E, 0.5, "offset"),
        ([1.0, 0.0, 0.0], 0.0, D_E, 0.5, "offset"),
        ([1.0, 0.0], math.inf, D_E, 0.5, "axis"),
        ([1.0, 0.0], 0.0, 0.0, 0.5, "positive"),
        ([1.0, 0.0], 0.0, D_E, -0.5, "positive"),
        ([0.0, 0.0], 0.0, D_E, 0.5, "same point"),
    ],
)
def test_errors(offset: list[float], axis: float, d_e: float, phi_e: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        check_pair(2, 1, np.array(offset), axis, d_e, phi_e)


def test_facing_misfit_worked_by_hand() -> None:
    from agent.core.formation.shape.verdict import facing_misfit

    # axis north; the parent straight ahead (line of sight north) facing north: its back,
    # orientation 0; turned 40° to the left: +40°; its front (orientation π): modulo π, 0
    ahead = np.array([0.0, D_E])
    assert facing_misfit(ahead, 0.0, math.pi / 2) == pytest.approx(0.0)
    assert facing_misfit(ahead, math.radians(40), math.pi / 2) == pytest.approx(math.radians(40))
    assert facing_misfit(ahead, math.pi, math.pi / 2) == pytest.approx(0.0, abs=1e-12)
    # the parent 30° to the right of the axis, facing north: orientation = north − LOS = +30°
    right = D_E * np.array([math.sin(PHI_E), math.cos(PHI_E)])
    assert facing_misfit(right, PHI_E, math.pi / 2) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="offset"):
        facing_misfit(np.zeros(2), 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        facing_misfit(ahead, math.nan, 0.0)


def test_a_robot_is_sure_only_with_a_margin() -> None:
    from agent.core.formation.shape.verdict import OWN_MARGIN

    phi = PHI_E * (1 + 0.9 * R_PHI_MAX)  # in tolerance, but within the camera's own error
    c = check_pair(2, 1, D_E * np.array([math.sin(phi), math.cos(phi)]), math.pi / 2, D_E, PHI_E)
    assert c.ok and not c.sure and OWN_MARGIN < 0.9
    c = check_pair(
        2, 1, D_E * np.array([math.sin(PHI_E), math.cos(PHI_E)]), math.pi / 2, D_E, PHI_E
    )
    assert c.sure


# ------------------------------------------------------------------ any shape's tree edge

LEFT, RIGHT = math.pi - PHI_E, PHI_E - math.pi  # the pyramid's tree angles


def test_an_edge_worked_by_hand() -> None:
    from agent.core.formation.shape.verdict import check_edge

    # axis north; a line's child belongs 0.8 m to its parent's left (angle 90°); it stands
    # 0.9 m away, 6° behind that line (parent − child = 0.9·(cos 6°, sin 6°))
    off = 0.9 * np.array([math.cos(math.radians(6)), math.sin(math.radians(6))])
    c = check_edge(2, 1, off, math.pi / 2, 0.8, math.pi / 2, PHI_E)
    assert c.r_d == pytest.approx(0.125)
    assert math.degrees(c.angle) == pytest.approx(96.0)  # the direction parent → child
    assert c.r_phi == pytest.approx(-6.0 / 30.0)  # towards the backward axis: negative
    assert c.ok
    # a column's child belongs straight behind; it stands 4° to the right of that line
    # (CCW from the facing: 184°), r_φ counted CCW: +4°/φ_e; 4° to the left: −4°/φ_e
    off = 0.8 * np.array([-math.sin(math.radians(4)), math.cos(math.radians(4))])
    c = check_edge(2, 1, off, math.pi / 2, 0.8, math.pi, PHI_E)
    assert c.r_phi == pytest.approx(4.0 / 30.0)
    c = check_edge(2, 1, off * np.array([-1.0, 1.0]), math.pi / 2, 0.8, math.pi, PHI_E)
    assert c.r_phi == pytest.approx(-4.0 / 30.0)


@given(
    st.floats(0.3, 2.0),
    st.floats(0.05, 1.5),
    st.floats(-math.pi, math.pi),
    st.booleans(),
)
def test_on_its_own_side_a_pyramid_edge_is_the_pair_check(
    d: float, phi: float, axis: float, left: bool
) -> None:
    from agent.core.formation.shape.verdict import check_edge

    # parent − child at φ off the axis, the child on its side (parent − child turned to the
    # right of the axis: the child behind-left): check_pair's unsigned angle and the edge's
    # signed one agree
    s = 1.0 if left else -1.0
    off = d * np.array([math.cos(axis - s * phi), math.sin(axis - s * phi)])
    a = check_pair(2, 1, off, axis, D_E, PHI_E)
    b = check_edge(2, 1, off, axis, D_E, LEFT if left else RIGHT, PHI_E)
    assert b.r_d == pytest.approx(a.r_d, abs=1e-12)
    assert b.r_phi == pytest.approx(a.r_phi, abs=1e-9)
    # on the wrong side the pair check passes, the edge fails: r_φ = −(φ + φ_e)/φ_e
    w = check_edge(2, 1, off, axis, D_E, RIGHT if left else LEFT, PHI_E)
    assert w.r_phi == pytest.approx(-(phi + PHI_E) / PHI_E, abs=1e-9)


@pytest.mark.parametrize(
    ("offset", "axis", "dist", "angle", "phi_e", "match"),
    [
        ([math.nan, 0.0], 0.0, 0.8, 0.0, 0.5, "offset"),
        ([1.0, 0.0, 0.0], 0.0, 0.8, 0.0, 0.5, "offset"),
        ([1.0, 0.0], math.inf, 0.8, 0.0, 0.5, "finite"),
        ([1.0, 0.0], 0.0, 0.8, math.nan, 0.5, "finite"),
        ([1.0, 0.0], 0.0, 0.0, 0.0, 0.5, "positive"),
        ([1.0, 0.0], 0.0, 0.8, 0.0, -0.5, "positive"),
        ([0.0, 0.0], 0.0, 0.8, 0.0, 0.5, "same point"),
    ],
)
def test_edge_errors(
    offset: list[float], axis: float, dist: float, angle: float, phi_e: float, match: str
) -> None:
    from agent.core.formation.shape.verdict import check_edge

    with pytest.raises(ValueError, match=match):
        check_edge(2, 1, np.array(offset), axis, dist, angle, phi_e)


def test_facing_tolerance_is_the_mask_error_bound_at_the_false_alarm_rate() -> None:
    """z_{1−α/2} σ_m, worked by hand: α = 0.05 gives 1.96 σ_m; the shipped model at the
    fault test's α = 10⁻⁴ gives 3.89 σ_m, about 26°; each bad input raises."""
    from agent.core.formation.frame.faults.fault_test import ALPHA
    from agent.core.formation.shape.verdict import facing_tolerance
    from agent.core.perception.sighting_noise import shipped_noise

    assert facing_tolerance(0.1, 0.05) == pytest.approx(0.19600, abs=1e-5)
    shipped = facing_tolerance(shipped_noise().sigma_mask, ALPHA)
    assert shipped == pytest.approx(3.8906 * shipped_noise().sigma_mask, rel=1e-4)
    assert math.radians(20.0) < shipped < math.radians(30.0)
    for sigma, alpha in ((0.0, 0.01), (math.pi / 4, 0.01), (0.1, 0.0), (0.1, 1.0)):
        with pytest.raises(ValueError, match="must be in"):
            facing_tolerance(sigma, alpha)
