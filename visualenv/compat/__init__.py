"""Every use of a dependency's internals or workaround of its behaviour, one module per dependency, each gated on the
versions it was checked against (and tested to fail loudly when the dependency moves)."""
