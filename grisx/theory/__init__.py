"""The estimator core of grisx, written once as Warp functions and structs.

=====================  ========================================================
module                 what it holds
=====================  ========================================================
``random``             counter-based uniforms: u = hash(seed, stream, counter)
``gris``               resampling weights: RIS (seed 000, Eq. 6), GRIS (Eq. 9),
                       W = 1/p for fresh candidates
``reservoir``          weighted reservoir: stream, merge, finalize W (Eq. 8),
                       confidence caps (seed 004, Alg. 1)
``mis``                generalized balance heuristic (seed 001, Eq. 15–16),
                       pairwise MIS, support-counting 1/Z (seed 004, Alg. 4),
                       the power heuristic of path tracing (Veach, Eq. 9.13)
``shift``              shift records and the reconnection Jacobian (seed 004,
                       Eq. 11)
``conditional``        conditional and joint UCWs (seed 001, Def. 4.1,
                       Thm. 4.1), conditional RIS, final gather (Eq. 13–23)
``gradient``           paired-pixel domains, gradient after/with ReSTIR,
                       positivization (seed 000, Eq. 2–26)
``control_variate``    spatio-temporal control variates and the ReSTIR
                       difference estimator (seed 002, Eq. 2–11)
``manifold``           Bernoulli-trial UCWs, trust regions, priors and the
                       manifold shift of SMS (seed 003, Eq. 1–13)
``toys``               problems with exact answers that run these functions
=====================  ========================================================

The toy integrators and the scene renderers call the same functions: the
estimator verified against a closed form here is the one that renders.
"""

from grisx.device import init as _init

_init()
