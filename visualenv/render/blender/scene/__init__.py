"""Building a Blender scene: what a plan declares, a user's .blend, an MJCF model.

* :mod:`.build`: load a .blend, add primitives, meshes, lights and cameras; track the data created
* :mod:`.blendfile`, :mod:`.describe`: a user's .blend read in a child process first (a file that crashes Blender
  cannot take this process down), and what it holds, as a spec writer needs it
* :mod:`.user_file`: what the env's copy of a user's scene keeps (a binding wins over the file)
* :mod:`.mjcf`: an MJCF model's geoms, lights and cameras as objects, posed from MuJoCo's arrays
* :mod:`.export`: a renderer's scene saved as a .blend that opens in Blender's GUI
"""
