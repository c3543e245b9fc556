"""Ray's internals that ``visualenv train --backend rllib`` reads: the local cluster's address, RLlib's deprecations.

**The local cluster.** ``--address auto`` is refused before anything starts when no Ray cluster runs on this machine,
with a message that says how to start one. ``ray.init("auto")`` finds the cluster through
``ray._private.services.find_gcs_addresses`` (the GCS processes' ``--gcs-address``, read from ``ps``); Ray has no
public call that asks without connecting. :func:`local_cluster_addresses` calls it on the Ray versions in
:data:`CHECKED` alone; elsewhere it says it cannot tell (None), and ``ray.init("auto")`` reports a missing cluster
itself.

**RLlib's deprecation warnings.** RLlib warns about its own deprecated constructors while it builds its own modules;
they go to the logger of the module that warns, :data:`DEPRECATION_LOGGER`, which visualenv quiets while it builds them.

``tests/compat/test_ray.py`` fails when Ray moves: another version, the call or the logger's module gone.

Checked against Ray 2.60.0 (the version the ``ray`` extra pins).
"""

from __future__ import annotations

#: the Ray versions (major.minor) whose internals were read for what this module relies on
CHECKED = ("2.60",)
#: the logger RLlib's deprecation warnings go to (the module ``ray._common.deprecation``'s)
DEPRECATION_LOGGER = "ray._common.deprecation"


def checked() -> bool:
    """Whether the installed Ray is one this module was checked against (this imports Ray)."""
    import ray

    return ".".join(ray.__version__.split(".")[:2]) in CHECKED


def local_cluster_addresses() -> set[str] | frozenset[str] | None:
    """The GCS addresses of the Ray clusters running on this machine (empty: none), as ``ray.init("auto")`` finds
    them; None on a Ray not in :data:`CHECKED`, where it cannot be told without connecting."""
    if not checked():
        return None
    from ray._private.services import find_gcs_addresses

    return find_gcs_addresses()
