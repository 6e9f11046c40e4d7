"""Properties, preferences and panels of the 3D View sidebar tab "Lightmap"."""
from . import panels, preferences, properties  # noqa: F401
