"""Recorded fleets where the frame is fragile, kept as known answers (docs/design.md §9):
each file of ``tests/data/runs`` holds the neighbour records a real run published (the
world rendering, the agents' own perception) and its true start poses, in the corpus's
format (``python -m tools.corpus``).

* ``n04_obstacle1_s1_*``: four NAOs and one obstacle (``python -m tools.demo --robots 4
  --seed 1 --obstacles 1``), the test of routing around an obstacle. Robot 2 sees robot 4
  at 0.63 m, from one of two pictures: in one of them the distance comes out 0.72 m
  (13 σ), and which picture a robot keeps depends on the timing of the search. Kept in
  the bias test, that one sighting among robot 2's three reads as a biased sensor
  (Λ 37) and leaves a sound robot out; the test sets the worst sighting aside. In ``_c``
  robot 2 kept the good picture.
* ``n50_random_s1018``: fifty NAOs set down at random (``python -m tools.corpus build``).
  The pose fit holds two sound robots half a turn off, 31 where it stands and 32 1.9 m
  away; turning 31 round fits better, and so does turning 32 after it. Turning only the
  first, the refined fit rejected 32 and the rest passed without it: a sound robot left
  out.

And fault runs of the corpus (``tests/data/frames``) where the faulty robot is named only
because the frame's choice follows the model:

* ``n07_jitter20_s1125+shift:0.5@2``: robot 7's sighting "of robot 2" is of another
  place. Left out, robot 2 must stand where the other five sightings of it agree, not at
  the mean of all six (0.18 m off, where every one of them lands nowhere and the rest
  fails its global test).
* ``n09_aligned_s1028+shift:0.5@2``: the aligned model with its sightings identified
  where they land absorbs robot 2 (every sighting of it re-identified) and passes with
  everyone, but its global test doubts it (p 10⁻³); the pose fit names robot 2 and the
  rest fits (p 0.4-0.9).
* ``n04_aligned_s1160+scale:1.4@2``: leaving robot 2 out, the rest fitted warm keeps a
  robot pulled round; fitted from the spanning tree as well (the lower cost kept), it
  passes, and robot 2 is named.
* ``n06_random_s1195+scale:1.4@5``: robot 5's sighting of robot 3, 40 % too long, was
  paired with robot 1, farther off, and one of its sightings paired with nobody. Its
  bias test, taking every sighting of its own where it lands, finds s 1.41 and no shift
  (Λ 83; with the fit's pairing kept, a scale and a shift traded off at Λ 30).
* ``n07_random_s1279+scale:1.4@6``: matched where they land from the pose fit's start,
  robot 6's sightings stay in a basin with a shift of 0.6 m (Λ 9); from the fit's
  pairing they reach s 1.47 (Λ 66), the lower cost.

* ``n07_random_s1105+shift:0.5@7``: robot 7 is rejected in every frame (p 6·10⁻⁹), but
  the rest fitted again from the pairs made with it fails; framed from scratch without
  its record, the rest passes, and robot 7 is named.
* ``n10_random_s1144+scale:1.4@8``: robot 10, sound, fits badly beside the faulty robot
  8 (its ψ 11° off, its masks disagreeing, p 4·10⁻¹⁰), and the two share no sighting.
  Leaving only the pairs of either out, the rest still fails: robot 8's record had
  shaped the pairing. Framed again from scratch without robot 10's record the rest fails
  (robot 8 rejected); without robot 8's it passes: robot 8 is named, and robot 10 fits.
* ``n07_random_s1159+scale:1.4@1``: in the fit of every record, robot 1 pulls the fit its
  way: four of its six pairs rejected (p 10⁻³) and a bias Λ 21 (p 4·10⁻³), not enough at
  α, and the dropped pairs leave it unconnected. Framed without its record, the rest
  passes; alone against it, four of its five sightings land nowhere (p 5·10⁻⁹), and
  robot 1 is named.
* ``n06_aligned_s1301+shift:0.5@3``: robot 3's one rejected pair cut the fleet; alone
  against the rest, all four of its sightings land nowhere (p 10⁻⁹).
* ``n10_jitter20_s1164+rotate:40@3``: robot 3's masks say its compass is 40° off (p
  5·10⁻¹¹), but the rest framed without its record failed its global test (p 8·10⁻⁵)
  for the others' sightings of robot 3, lost strays. Counted as landing where robot 3
  stands, they let the rest pass, and robot 3 is named.

And one where the fault is absorbed, the frame right:
* ``n11_aligned_s1037+scale:1.4@5``: the pose fit rejects robot 5 and the rest fits
  (p 0.58), but robot 5's record, tested alone against that rest, passes (its distances
  1.4 times too long land on other robots of a dense fleet often enough): a rejection in
  the fit that the record alone does not confirm may be another robot's pull, and names
  nobody. The refined pose fit re-identifies robot 5's sightings onto its neighbours and
  passes with everyone; every start is within tolerance. Even against the others' true
  poses its record is rejected only at p 1.2·10⁻⁴, above α: beyond what the records
  reveal.
And one where nobody can be named, and nobody is:

* ``n06_jitter20_s1287+shift:0.5@2``: in six robots, robot 2's sightings are shifted;
  set aside, the rest framed from scratch still rejects a sound robot (three of its four
  pairs fail): no single robot explains the records, and the fleet stops.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from agent.adapters import FormationAdapter
from agent.core.formation.frame.fleet_frame import fleet_frame
from agent.core.formation.frame.neighbour_check import DEFAULT_EPSILON
from tools.corpus import runs_of
from tools.lib.frame_fit import frame_error

DATA = Path(__file__).parents[2] / "data"
RUNS = sorted((DATA / "runs").glob("*.json"))
NAMED = [
    "n07_jitter20_s1125+shift:0.5@2",
    "n09_aligned_s1028+shift:0.5@2",
    "n04_aligned_s1160+scale:1.4@2",
    "n06_random_s1195+scale:1.4@5",
    "n07_random_s1279+scale:1.4@6",
    # re-identified onto its neighbours, the shifted robot's sightings made a frame one
    # start 0.47 m off that everyone passed: doubted by its most surprising robot
    "n07_aligned_s1259+shift:0.5@1",
    "n10_random_s1144+scale:1.4@8",
    "n07_random_s1105+shift:0.5@7",
    "n07_random_s1159+scale:1.4@1",
    "n06_aligned_s1301+shift:0.5@3",
    "n10_jitter20_s1164+rotate:40@3",
]


def test_the_recorded_runs_are_there() -> None:
    assert len(RUNS) >= 3


@pytest.mark.parametrize("path", RUNS, ids=[p.stem for p in RUNS])
def test_every_sound_robot_is_planned_and_placed(path: Path) -> None:
    run = runs_of(path)[0]  # as recorded: no fault
    assert run.fault == ""
    ff = fleet_frame(FormationAdapter.records(run.records), DEFAULT_EPSILON)
    assert ff.excluded == () and set(ff.ids) == set(run.truth), ff.reason
    est = {i: (ff.positions[k], ff.heading_of(i)) for k, i in enumerate(ff.ids)}
    pos_err, psi_err = frame_error(est, run.truth)
    assert pos_err < 0.15 and psi_err < 0.17, (pos_err, psi_err)


@pytest.mark.parametrize("name", NAMED)
def test_the_faulty_robot_is_named(name: str) -> None:
    fleet = name.partition("+")[0]
    (run,) = [r for r in runs_of(DATA / "frames" / f"{fleet}.json") if r.name == name]
    ff = fleet_frame(FormationAdapter.records(run.records), DEFAULT_EPSILON)
    assert ff.excluded == (run.victim,), ff.reason
    est = {i: (ff.positions[k], ff.heading_of(i)) for k, i in enumerate(ff.ids)}
    pos_err, psi_err = frame_error(est, {i: t for i, t in run.truth.items() if i in ff.ids})
    assert pos_err < 0.15 and psi_err < 0.17, (pos_err, psi_err)


def test_a_fault_the_records_barely_reveal_is_absorbed_in_a_right_frame() -> None:
    name = "n11_aligned_s1037+scale:1.4@5"
    (run,) = [r for r in runs_of(DATA / "frames" / "n11_aligned_s1037.json") if r.name == name]
    ff = fleet_frame(FormationAdapter.records(run.records), DEFAULT_EPSILON)
    assert ff.excluded == (), ff.reason
    est = {i: (ff.positions[k], ff.heading_of(i)) for k, i in enumerate(ff.ids)}
    pos_err, psi_err = frame_error(est, run.truth)
    assert pos_err < 0.15 and psi_err < 0.17, (pos_err, psi_err)


def test_a_sound_robot_rejected_for_anothers_fault_is_not_named() -> None:
    """Six NAOs beside a bystander on a slot (``tests/data/bystanders``), robot 2's compass
    40° off: in the pose fit its sightings pull robot 3's pairs off (four of four
    rejected), and without robot 3 the rest passes, robot 2's turn absorbed in its ψ.
    Robot 3's record, tested alone against that rest, fits (p 1): it is not named, and
    the fleet stops rather than leave a sound robot out (the last frame's words: robot
    2's masks reject it, and no single robot explains it)."""
    name = "n06_aligned_s3060_b1slot+rotate:40@2"
    path = DATA / "bystanders" / "n06_aligned_s3060_b1slot.json"
    (run,) = [r for r in runs_of(path) if r.name == name]
    with pytest.raises(ValueError, match=r"no frame passes the fault test.*robot 2: .*masks -45°"):
        fleet_frame(FormationAdapter.records(run.records), DEFAULT_EPSILON)


def test_records_no_single_robot_explains_stop_the_fleet() -> None:
    name = "n06_jitter20_s1287+shift:0.5@2"
    (run,) = [r for r in runs_of(DATA / "frames" / "n06_jitter20_s1287.json") if r.name == name]
    with pytest.raises(ValueError, match="beyond one robot"):
        fleet_frame(FormationAdapter.records(run.records), DEFAULT_EPSILON)
