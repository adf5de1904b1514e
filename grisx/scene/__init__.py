"""Scene layer: Warp scenes, loaders and renderers that call the estimator core in grisx.theory (see DESIGN.md)."""
