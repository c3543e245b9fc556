"""Every use of a dependency's internals or undocumented behaviour, in one place.

visualenv leans on its dependencies beyond their documented API in a few spots: the C library's allocator,
MKL's reproducibility mode inside torch, Gymnasium's ``make`` and a space's generator, Blender's and Cycles'
private calls, Ray's and Stable-Baselines3's private calls, and MuJoCo's fields that changed between the versions
supported. Spread through the code, such workarounds contradict each other and break silently when a dependency
moves; here each is found, named and checked. The rule:

* one module per dependency (:mod:`~visualenv.compat.glibc`, :mod:`~visualenv.compat.mkl`,
  :mod:`~visualenv.compat.gymnasium`, :mod:`~visualenv.compat.blender`, :mod:`~visualenv.compat.mujoco`,
  :mod:`~visualenv.compat.ray`, :mod:`~visualenv.compat.sb3`), and nothing outside this package reaches a
  dependency's internals (``tests/compat/test_private_access.py`` searches the package for ``ctypes``, ``mallopt``,
  ``malloc_trim``, frame inspection and MKL's service calls, for imports of another package's private modules
  and names, and for ``X._name`` where visualenv defines no ``_name``);
* each module says which versions it was checked against and uses its workaround only on those (elsewhere
  the documented behaviour, or nothing, with the difference said);
* each has a test that fails loudly when its dependency moves (a version outside those checked, a symbol or a
  behaviour gone), so that an upgrade is a decision, not a surprise;
* the documented mechanism wins wherever one exists (an environment variable, an attribute Gymnasium sets);
  a workaround says why the documented way cannot do its job.

Nothing here changes a user's process merely because an env was made, stepped or closed: process-wide
settings are applied by the processes visualenv owns (its CLI commands and the worker processes it starts).
"""
