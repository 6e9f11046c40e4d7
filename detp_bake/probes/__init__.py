"""Light probes: baked incident light at points in space, for what moves through a baked level.

`sh9.py` holds the second-order spherical-harmonic convention every part shares; `grid.py` the
probes' places and values as one record, and its plain file."""
