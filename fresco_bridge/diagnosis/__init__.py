"""Sim-to-real gap diagnosis: where a test departs from its simulation, which unmodelled effect
causes it, and how far the gap shrinks once that effect is added (``fresco-bridge diagnose``).

Heavy modules (scipy, numba kernels, matplotlib) load inside the commands, never at import of
the bridge.
"""
