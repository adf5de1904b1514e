"""Scene layer: what a scene *is* — builder and BVH, shapes, Mitsuba XML loader, built-in scenes, camera, BSDFs, lights, textures, G-buffer. Renderers live in :mod:`grisx.render` (see DESIGN.md)."""
