"""Blender's status lines sort a render call into phases: each stretch goes to the line that opened it."""

import pytest

from visualenv.tools.render_events import UPDATE_MARK, label_of, marked_call, phase_of, split_call


@pytest.mark.parametrize(
    "line, phase",
    [
        ("Mem: 1M | Synchronizing object | cart", "sync.objects"),
        ("Mem: 1M | Updating Lights | Computing tree", "sync.lights"),
        ("Mem: 1M | Updating Background", "sync.world"),
        ("Mem: 1M | Updating Shaders", "sync.shaders"),
        ("Mem: 1M | Updating Images", "sync.images"),
        ("Fra:1 | Mem: 1M | Updating Scene BVH | Building BVH", "bvh"),
        ("Mem: 1M | Sample 0/4", "trace"),
        ("Mem: 1M | Sample 3/4", "trace"),
        ("Mem: 1M | Sample 4/4", "film"),
        ("Mem: 1M | Finished", "film"),
        ("Mem: 1M | Updating Camera", ""),
        (UPDATE_MARK, "sync.start"),
    ],
)
def test_each_status_line_opens_its_phase(line, phase):
    assert phase_of(line) == phase


def test_a_line_is_labelled_without_blenders_figures():
    assert label_of("Fra:1 | Mem: 12.5M | Updating Lights | Computing tree") == "Updating Lights | Computing tree"


def test_a_call_is_split_at_its_lines_and_the_stretches_add_up_to_it():
    events = [
        (0.5, "Mem: 1M | Sample 9/9"),  # before the call: not counted
        (11.0, UPDATE_MARK),
        (12.0, "Mem: 1M | Synchronizing object | cart"),
        (14.0, "Mem: 1M | Updating Camera"),  # unnamed before the samples: sync's other
        (15.0, "Mem: 1M | Updating Scene BVH | Building BVH"),
        (18.0, "Mem: 1M | Sample 0/1"),
        (25.0, "Mem: 1M | Sample 1/1"),
        (26.0, "Mem: 1M | Cycles' own afterword"),  # unnamed after the samples: film
        (40.0, "Mem: 1M | Sample 0/1"),  # after the call: not counted
    ]
    split = split_call(10.0, 30.0, events)
    assert split.seconds == {
        "depsgraph": 1.0,
        "sync.start": 1.0,
        "sync.objects": 2.0,
        "sync.other": 1.0,
        "bvh": 3.0,
        "trace": 7.0,
        "film": 5.0,
        "sync.lights": 0.0,
        "sync.world": 0.0,
        "sync.shaders": 0.0,
        "sync.images": 0.0,
    }
    assert split.total("sync") == 4.0 and sum(split.seconds.values()) == 20.0
    assert split.events == {"sync.start": 1, "sync.objects": 1, "sync.other": 1, "bvh": 1, "trace": 1, "film": 2}
    assert split.labels["Sample 0/1"] == 7.0 and split.labels["(before Cycles' update)"] == 1.0


def test_a_call_without_lines_is_all_blenders_own():
    split = split_call(1.0, 3.0, [])
    assert split.seconds["depsgraph"] == 2.0 and split.total("sync") == 0.0


def test_a_call_is_cut_at_the_first_of_each_of_cycles_marks():
    marks = [(0.5, "render_end"), (2.0, "update"), (3.0, "update_end"), (3.5, "render"), (8.0, "render_end")]
    assert marked_call(1.0, 9.0, marks) == {
        "before_update": 1.0,
        "cycles_update": 1.0,
        "between": 0.5,
        "cycles_render": 4.5,
        "after_render": 1.0,
    }
    assert marked_call(1.0, 9.0, marks[:3]) is None  # Cycles never rendered: nothing to cut
