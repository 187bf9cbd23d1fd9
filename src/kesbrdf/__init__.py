"""kesbrdf: anisotropic fabric BRDFs from the extended KES method (Takeda et al.).

Layers (DESIGN §6): io → measurement → kes → model → brdf → validation, with plotting,
render, viewer and cli on top.  Only numpy is needed for the core.
"""

from kesbrdf._version import __version__

__all__ = ["__version__"]
