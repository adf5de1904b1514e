"""Render layer: what renders a scene — the frame driver, the reference path tracer, one file per
renderer (ReSTIR DI, GI, PT, ...), the path shifts and screen-space reuse they share, views,
references and the render CLI. Imports point one way: render → scene → theory (see DESIGN.md).

``from grisx.render import render`` is the driver's entry point (:func:`grisx.render.driver.render`).
"""

from grisx.render.driver import METHODS, RenderResult, render

__all__ = ["METHODS", "RenderResult", "render"]
