"""Standard opacity micromaps (VK_EXT/KHR_opacity_micromap, DXR 1.2): bake, reuse, expand the
deck's square maps into them, write and verify the files an engine loads."""
