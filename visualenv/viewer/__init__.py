"""The live web viewer: `visualenv view` (play a spec with the keys, watch an agent, edit the spec and see it rebuilt)
and ``render_mode="human"`` (an env's steps shown on the same page).

The parts, lowest first: :mod:`board` (what the page shows, handed between threads), :mod:`server` (the HTTP server,
Werkzeug) and :mod:`page` (the page: HTML and a little inline JavaScript), :mod:`human` (the hook the envs call in
``render_mode="human"``); above the envs: :mod:`controls` (keys and sliders of a spec's actions), :mod:`watch` (the
files an edit rebuilds on), :mod:`session` (the loop that steps the env) and :mod:`app` (what `visualenv view` runs).

Nothing is imported here: the envs import :mod:`human` on their first human-mode frame, and ``import visualenv``
never loads the web library.
"""
