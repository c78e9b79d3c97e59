"""Stage 3, the precompute: the light-dependent cut, the point-light bake (local PRT) and the distant-light transfer
bake, and the float64 Embree reference bake the tests check them against. Writes stores (``lodprt.store``); never
imports the run time or the display (docs/ARCHITECTURE.md)."""
