"""detp_bake core: photon tracing and density estimation for lightmaps, with no Blender import.

Only `blender` talks to Blender; everything else takes numpy arrays and dataclasses.
"""
__version__ = "0.1.0"
