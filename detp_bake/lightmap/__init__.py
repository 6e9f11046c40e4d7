"""The lightmaps' texels: rasterised charts, validity, sites, noise, denoising and images."""
