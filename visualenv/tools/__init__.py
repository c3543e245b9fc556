"""The command's tools on top of the env and training layers: ``build``/``preview``, ``bench``, ``bench-rllib``,
and ``inspect``/``init`` for a user's .blend (:mod:`~visualenv.tools.starter`)."""
