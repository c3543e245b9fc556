"""Fixtures shared by several test modules, and the `blender` marker.

``pytest -m "not blender"`` runs the bpy-free core (spec loading, expressions,
the compiler, the state-only env, wrappers, the CLI's checks) without
rendering; ``pytest`` runs everything. Tests that need Blender are marked here,
in one place, by module (and by test for a module that is mostly bpy-free), so
a new test file that renders is added to BLENDER_MODULES.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CORPUS_SCRIPT = Path(__file__).parent / "fixtures" / "blend_corpus.py"

#: modules whose tests render with real Blender, read .blend files, or start processes that do
BLENDER_MODULES = {
    "test_api_strict",
    "test_batched",
    "test_batched_instances",
    "test_batched_scale",
    "test_batched_tracking",
    "test_bench_and_soak",
    "test_blend_corpus",
    "test_blend_scripts_off",
    "test_build_and_preview",
    "test_capture",
    "test_compat_blender",
    "test_determinism",
    "test_distractions",
    "test_dmc_pixels",
    "test_evaluation",
    "test_heightmap",
    "test_inspect_init",
    "test_make_options",
    "test_mujoco_look",
    "test_parallel",
    "test_physics_scene",
    "test_quiet_exit",
    "test_render_blender",
    "test_rendering_determinism",
    "test_rllib",
    "test_segmentation",
    "test_sensor",
    "test_shipped_models",
    "test_sky_textures",
    "test_texture_sets",
    "test_train_play",
    "test_viewer",
    "test_viewer_browser",
    "test_viewer_human",
}
#: single tests that render, in modules that otherwise do not
BLENDER_TESTS = {
    "test_runtime_faults.py::test_a_binding_fault_while_rendering_obeys_on_fault",
    "test_bindables.py::test_the_blender_backend_has_a_setter_for_every_bindable_property",
    "test_first_hour.py::test_build_says_an_rgb_observation_is_sketched_in_grayscale",
    "test_pickle_episode.py::test_a_rendered_env_goes_on_with_its_frames_and_sensor_noise",
    "test_specs_import_nothing.py::test_build_renders_a_package_model_without_importing_the_package",
    "test_bundled_ports.py::test_building_half_cheetah_prints_nothing_on_stderr",
    "test_physics_mocap.py::test_the_goal_is_drawn_where_its_mocap_pose_puts_it_alone_and_in_a_batch",
    "test_physics_sites.py::test_a_red_site_in_view_shows_red_pixels_alone_and_in_a_batch_and_draw_sites_false_hides_it",
}


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        module = item.path.stem
        if module in BLENDER_MODULES or f"{item.path.name}::{item.name}" in BLENDER_TESTS:
            item.add_marker(pytest.mark.blender)


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """The .blend corpus (tests/fixtures/blend_corpus.py), written once per test session."""
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("blend_corpus")
    subprocess.run([sys.executable, str(CORPUS_SCRIPT), str(folder)], check=True, capture_output=True, timeout=300)
    return folder
