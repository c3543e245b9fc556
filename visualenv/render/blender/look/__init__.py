"""How a scene looks: materials, the world, MuJoCo's look, distractions and segmentation.

* :mod:`.materials`: Principled BSDF materials, procedural and image textures, the world background
* :mod:`.mujoco`: a model lit and coloured as MuJoCo's OpenGL renderer draws it (``physics.look: mujoco``)
* :mod:`.distraction_scene`: a distraction drawn in the scene: cameras moved, colours shifted, a backdrop
* :mod:`.segmentation`: each pixel holds the id of the object it sees
"""
