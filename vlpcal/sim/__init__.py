"""vlpcal's test bench: simulated installs, frames and surveys (no one has the paper's lab).

- :mod:`vlpcal.sim.render`: pixel-level rendering of spots (PSF integrated over pixels, noise,
  saturation, quantisation, JPEG).
- :mod:`vlpcal.sim.scene`: true vs nominal cameras drawn from named error profiles, and frames
  of an LED anywhere in the room as each true camera would take them.
- :mod:`vlpcal.sim.profiles`: the named profiles (``paper-2024``, ``cheap-wide``, ``qvga``).
- :mod:`vlpcal.sim.writers`: survey bundles, ``locate`` frame folders and deployment files.
"""

from .render import Sensor, SpotLook, add_spots, encode_jpeg, render, render_views

__all__ = ["Sensor", "SpotLook", "add_spots", "encode_jpeg", "render", "render_views"]
