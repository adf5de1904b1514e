"""Shading frames: the orthonormal basis (s, t, n) in which every BSDF is written.

BSDFs are defined in a *local* frame whose z axis is the shading normal, so
that cos θ of a direction is just its z component and the lobes need no
knowledge of the surface's orientation in the world. A renderer builds the
frame once per hit from the shading normal,

    s, t = basis(n),   v_local = (v·s, v·t, v·n),   v_world = v_x s + v_y t + v_z n,

and converts directions in and out of it (``to_local`` / ``to_world``).

The basis is the branchless construction of Duff et al. (their Listing 3):
with σ = sign(n_z) (σ = +1 for n_z = 0), a = −1/(σ + n_z), b = n_x n_y a,

    s = (1 + σ n_x² a,  σ b,  −σ n_x),    t = (b,  σ + n_y² a,  −n_y).

It is continuous everywhere except across n_z = 0 (no continuous tangent field
exists on the sphere), exact in floating point near the poles where the older
Frisvad construction loses accuracy, and identical to Mitsuba 3's
``coordinate_system``, so local directions match Mitsuba's bit for bit in
exact arithmetic.

References: T. Duff, J. Burgess, P. Christensen, C. Hery, A. Kensler, M. Liani,
R. Villemin, "Building an orthonormal basis, revisited", JCGT 6(1), 2017;
W. Jakob et al., Mitsuba 3, ``include/mitsuba/core/vector.h``.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

__all__ = ["Frame", "frame_from_normal", "to_local", "to_world"]


@wp.struct
class Frame:
    """Orthonormal shading frame: tangent ``s``, bitangent ``t``, normal ``n`` (right-handed, s × t = n)."""

    s: wp.vec3
    t: wp.vec3
    n: wp.vec3


@wp.func
def frame_from_normal(n: wp.vec3) -> Frame:
    """Frame around the unit normal ``n`` (Duff et al. 2017, Listing 3; branchless)."""
    sign = wp.sign(n[2])  # +1 for n_z = 0, as copysign(1, +0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    f = Frame()
    f.s = wp.vec3(1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    f.t = wp.vec3(b, sign + n[1] * n[1] * a, -n[1])
    f.n = n
    return f


@wp.func
def to_local(f: Frame, v: wp.vec3) -> wp.vec3:
    """World direction → local coordinates (z along the normal)."""
    return wp.vec3(wp.dot(v, f.s), wp.dot(v, f.t), wp.dot(v, f.n))


@wp.func
def to_world(f: Frame, v: wp.vec3) -> wp.vec3:
    """Local coordinates → world direction."""
    return f.s * v[0] + f.t * v[1] + f.n * v[2]
