"""Settings for the whole suite.

Tests that need test hosts (network namespaces and iptables: root, iproute2) take the
``netns_hosts`` fixture: skipped on a developer's machine without them, failed under
``CI`` (``.ci/run`` installs them), so that a CI run never passes by skipping them.

Hypothesis draws new examples on every run by default: a property that breaks on a rare
input then fails one CI run in many, which is a flaky test (the release points' property
found a 1e-12 m path once). In CI (``CI`` set, as ``.ci/run`` does) the examples are
derived from each test's name, so a run is repeatable; elsewhere they stay random, so a
developer's runs keep exploring, and a failure prints the example to pin.
"""

from __future__ import annotations

import os
import shutil

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def netns_missing() -> str | None:
    """Why test hosts cannot be made here (no iptables, no network namespaces), or None."""
    from tools import netns

    if shutil.which("iptables") is None:
        return "iptables is not installed"
    return netns.unavailable_reason()


def require_hosts(why: str | None, ci: bool) -> None:
    """Nothing when test hosts are available (``why`` None); else skip, or fail under CI."""
    if why is None:
        return
    if ci:
        pytest.fail(f"CI: the test needs iptables and network namespaces: {why}")
    pytest.skip(f"needs iptables and network namespaces: {why}")


@pytest.fixture
def netns_hosts() -> None:
    """Test hosts are available: else skip, or under ``CI`` fail (module docstring)."""
    require_hosts(netns_missing(), bool(os.environ.get("CI")))
