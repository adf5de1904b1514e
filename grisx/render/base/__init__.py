"""The machinery renderers share — and the only part of :mod:`grisx.render` a renderer imports.

``screen``      the frame record, one random-key scheme, pixel writes, the renderer base class
``trace``       the path tracer's inner loop (``trace_path``), called by pt and ReSTIR GI alike
``reuse``       screen-space reuse: who may reuse from whom (similarity, reprojection, neighbours)
``path_shift``  path records and the replay / reconnection / hybrid shifts of path-reuse renderers
``registry``    the plugin interface: a renderer registers itself, its params and defaults here

Renderers (:mod:`grisx.render.pt`, ``restir_di``, ``restir_gi``, ``restir_pt``, …) import these,
:mod:`grisx.scene` and :mod:`grisx.theory`, never each other.
"""
