"""Light transport: emission, photon tracing, scattering, textures and direct light."""
