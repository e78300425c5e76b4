"""agent/config.py: the agent's settings written back as its command line
(:meth:`AgentConfig.to_argv`), the inverse of ``python -m agent``'s parser."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.__main__ import agent_config, parse_args
from agent.config import AgentConfig
from agent.core.formation.params import D_E, PHI_E_DEG, PLAN_STRATEGIES
from agent.core.formation.shape.pyramid import ORIENTATIONS
from agent.core.formation.view.route import Route
from agent.core.perception.sensor_fault import SensorFault
from agent.wire import MAX_ROBOT_ID


def parsed(cfg: AgentConfig, claim_id: bool = False) -> AgentConfig:
    """What an agent started with ``cfg.to_argv()`` runs with."""
    return agent_config(parse_args(cfg.to_argv(claim_id=claim_id)), cfg.robot_id)


def positive(hi: float) -> st.SearchStrategy[float]:
    return st.floats(min_value=1e-3, max_value=hi, allow_nan=False, allow_infinity=False)


routes = st.one_of(
    st.none(),
    st.builds(lambda d: Route(distance=d), positive(50.0)),
    st.builds(
        lambda x, y: Route(to=(x, y)),
        st.floats(-1000.0, 1000.0, allow_nan=False),
        st.floats(-1000.0, 1000.0, allow_nan=False),
    ),
)
faults = st.one_of(
    st.none(),
    st.builds(SensorFault, st.just("rotate"), st.floats(-360.0, 360.0, allow_nan=False)),
    st.builds(SensorFault, st.just("scale"), st.floats(0.1, 10.0, allow_nan=False)),
    st.builds(SensorFault, st.just("shift"), st.floats(-5.0, 5.0, allow_nan=False)),
)
configs = st.builds(
    AgentConfig,
    robot_id=st.integers(0, MAX_ROBOT_ID),
    fleet_size=st.one_of(st.none(), st.integers(1, 200)),
    d_e=st.one_of(st.just(D_E), positive(10.0)),
    # phi_e as --phi-e-deg gives it: the radians of some degrees in (0, 90)
    phi_e=st.one_of(
        st.just(math.radians(PHI_E_DEG)),
        st.floats(0.01, 89.99, allow_nan=False).map(math.radians),
    ),
    orientation=st.sampled_from(ORIENTATIONS),
    strategy=st.sampled_from(PLAN_STRATEGIES),
    timeout=st.one_of(st.just(AgentConfig.timeout), positive(1e5)),
    wave_timeout=st.one_of(st.just(AgentConfig.wave_timeout), positive(1e5)),
    member_grace=st.one_of(st.just(AgentConfig.member_grace), positive(1e3)),
    correct=st.booleans(),
    march=routes,
    research_rounds=st.integers(0, 10),
    explore_step=st.floats(0.2, 5.0, allow_nan=False),
    sensor_fault=faults,
    publish_camera=st.booleans(),
)


@settings(deadline=None)  # argparse on a loaded machine: no timing to hold
@given(configs)
def test_the_command_line_gives_the_config_back(cfg: AgentConfig) -> None:
    assert parsed(cfg) == cfg


def test_only_what_differs_from_the_defaults_is_written() -> None:
    assert AgentConfig(robot_id=3).to_argv() == ["--id", "3"]
    assert AgentConfig(robot_id=3, fleet_size=4).to_argv(claim_id=True) == [
        "--id", "auto", "--fleet-size", "4",
    ]  # fmt: skip
    cfg = AgentConfig(robot_id=1, d_e=0.9, phi_e=math.radians(40.0), timeout=60.0,
                      correct=False, march=Route(to=(-1.5, 2.0)))  # fmt: skip
    assert cfg.to_argv() == ["--id", "1", "--phi-e-deg", "40.0", "--d-e=0.9", "--timeout=60.0",
                             "--no-correct", "--march-to=-1.5,2.0"]  # fmt: skip
    assert parsed(cfg) == cfg and cfg.phi_e_deg == 40.0
    assert AgentConfig(robot_id=1).phi_e_deg == PHI_E_DEG


def test_a_setting_no_flag_carries_is_refused() -> None:
    with pytest.raises(ValueError, match="settle"):
        AgentConfig(robot_id=1, settle=1.0).to_argv()
