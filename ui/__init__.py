"""Properties and panels of the 3D View sidebar tab "Lightmap"."""
from . import panels, properties  # noqa: F401
