"""The live web viewer: `visualenv view` (play a spec with the keys, watch an agent, edit the spec and see it rebuilt)
and ``render_mode="human"`` (an env's steps shown on the same page).

The parts, lowest first: :mod:`board` (what the page shows, handed between threads), :mod:`server` (the HTTP server,
Werkzeug) and :mod:`page` (the page: HTML and a little inline JavaScript), :mod:`human` (the display the envs show
their steps on in ``render_mode="human"``); :mod:`controls` (keys and sliders of a spec's actions), :mod:`watch` (the
files an edit rebuilds on), :mod:`session` (the loop that steps the env) and :mod:`app` (what `visualenv view` runs).

The envs sit below the viewer and never import it: ``import visualenv`` calls :func:`register_human_mode`, which hands
the env layer's hook (:mod:`visualenv.env.human`) a factory that imports :mod:`human` on the first human-mode env, so
``import visualenv`` never loads the web library.
"""

from __future__ import annotations

from visualenv.env.human import HumanDisplay, register_human_display


def open_display() -> HumanDisplay:
    """A new display on the viewer's shared page (the page's server starts with the first one)."""
    from visualenv.viewer.human import PageDisplay

    return PageDisplay()


def register_human_mode() -> None:
    """Makes ``render_mode="human"`` show envs on the viewer's page (what ``import visualenv`` does)."""
    register_human_display(open_display)
