"""The shipped agents' records, without rendering: the fast tier's guard that a bundled spec or an agent's file
changed (the slow tier replays them: test_shipped_models.py)."""

import hashlib
import json
from pathlib import Path

import pytest

from tests.train.test_shipped_models import SHIPPED
from visualenv.env.registration import resolve
from visualenv.train.model_files import pretrained_model


@pytest.mark.parametrize("env_id", SHIPPED)
def test_each_shipped_policy_names_the_spec_it_plays(env_id):
    """policy.json records the sha256 of the bundled spec the agent replays its results on: an edit to that spec
    fails here, in the fast tier, until its agent is replayed (the slow tier) and the record is brought up to date."""
    recorded = json.loads(pretrained_model(env_id).with_suffix(".json").read_text())["spec"]
    assert recorded["id"] == env_id
    assert recorded["sha256"] == hashlib.sha256(Path(resolve(env_id)).read_bytes()).hexdigest()


@pytest.mark.parametrize("env_id", SHIPPED)
def test_each_shipped_policy_is_small(env_id):
    """Shipped policies are float16 files of at most 6 MB: the repository stays clonable as agents are added."""
    assert pretrained_model(env_id).stat().st_size <= 6_000_000
    assert pretrained_model(env_id).with_suffix(".json").stat().st_size <= 10_000
