"""Dependencies' internals and behaviour that visualenv relies on or works around: one module per dependency."""
