"""Every use of a dependency's internals or private behaviour, one module per dependency, each gated on the versions it was checked against."""
