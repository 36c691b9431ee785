"""vlpcal: calibrated 3D visible light positioning from a few cheap ceiling cameras.

Layers, each importing only those before it (import-linter checks it): geometry → detection →
triangulation → fusion → deployment → survey / planning → cli. Units are metres and radians;
the world is z-up with the floor at z = 0 (docs/conventions.md).
"""

__version__ = "0.1.0"
