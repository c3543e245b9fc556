"""Ray's internals (visualenv/compat/ray.py): the local cluster's addresses and RLlib's deprecation logger, checked on
the installed Ray; --address auto is refused only where Ray says no cluster runs."""

from __future__ import annotations

import importlib
import logging

import pytest

ray = pytest.importorskip("ray")
from visualenv.compat import ray as compat  # noqa: E402
from visualenv.errors import ConfigError  # noqa: E402


def test_ray_is_a_version_this_module_was_checked_against():
    """Fails when Ray moves: read ray._private.services.find_gcs_addresses and ray._common.deprecation in it, then add
    its version to CHECKED."""
    assert compat.checked(), f"ray {ray.__version__} is not in compat/ray.py's CHECKED {compat.CHECKED}"


def test_the_local_cluster_is_asked_of_ray_and_an_unchecked_ray_cannot_tell(monkeypatch):
    services = importlib.import_module("ray._private.services")  # ImportError here: Ray moved the call
    found = compat.local_cluster_addresses()
    assert isinstance(found, (set, frozenset)) and found == services.find_gcs_addresses()
    monkeypatch.setattr(ray, "__version__", "9.9.0")
    assert compat.local_cluster_addresses() is None


def test_rllibs_deprecation_warnings_go_to_the_logger_quieted():
    module = importlib.import_module(compat.DEPRECATION_LOGGER)  # ImportError here: Ray moved the module
    assert isinstance(module.logger, logging.Logger) and module.logger.name == compat.DEPRECATION_LOGGER


@pytest.mark.parametrize(
    "found, environment, refused",
    [
        (frozenset(), {}, True),
        (frozenset({"127.0.0.1:6379"}), {}, False),
        (None, {}, False),
        (frozenset(), {"RAY_ADDRESS": "10.0.0.1:6379"}, False),
    ],
)
def test_address_auto_is_refused_where_ray_finds_no_cluster(found, environment, refused, monkeypatch):
    rllib_setup = pytest.importorskip("visualenv.train.rllib_setup")
    monkeypatch.setattr(rllib_setup, "local_cluster_addresses", lambda: found)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    if refused:
        with pytest.raises(ConfigError, match="no Ray cluster runs on this machine"):
            rllib_setup.check_address("auto")
    else:
        rllib_setup.check_address("auto")
