"""Many envs in one Blender scene, rendered by one Cycles call per camera (used where N > 1).

* :mod:`.renderer`: :class:`~visualenv.render.blender.batch.renderer.BatchedBlenderRenderer`
* :mod:`.calls`: how the envs are split into render calls (how many tiles one image holds)
* :mod:`.tiles_camera`: the custom camera whose tile k sees env k's copy of the scene
* :mod:`.env_cameras`: each env's camera: which cameras move or turn, their copies following, their rays turned
* :mod:`.copies`: env k's objects under an anchor at k's place on a grid; each copy's own lights
* :mod:`.instances`, :mod:`.instance_nodes`: meshes drawn as Geometry Nodes instances posed from numpy
* :mod:`.env_attributes`: numbers each env's shaders read (its colours, its distraction)
* :mod:`.distraction_draws`: each env's own distraction in one render
"""
