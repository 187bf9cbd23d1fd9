"""The one base of the reference BRDFs: a callable ``f(wi, wr) -> (..., C)`` in 1/sr.

Every reference (Ward, Ashikhmin–Shirley, Sadeghi 2013, Irawan 2012, MERL, the RGL
tensor files in numpy and through Mitsuba) writes only its *core*: f_r for unit pairs
above the horizon, rows (n, 3) -> (n, C).  The edges are handled once, by the same front
end the model kinds use (:func:`kesbrdf.models.mappings.evaluate_pairs`,
docs/architecture.md "The model contract"):

* ``wi`` and ``wr`` of shape (..., 3) broadcast; any length > 0 is normalised;
* a pair with a non-finite component gives NaN in every channel;
* a pair with a zero vector or cos θ ≤ :data:`kesbrdf.models.mappings.COS_EPS` for
  either direction is at or below the horizon and gives exactly 0;
* the core runs on the remaining pairs only, in chunks (:attr:`ReferenceBRDF.chunk`).
"""

from __future__ import annotations

import numpy as np

from kesbrdf.errors import KesbrdfError
from kesbrdf.models.mappings import EVAL_CHUNK, evaluate_pairs

__all__ = ["ReferenceBRDF", "default_channels"]


def default_channels(count: int, prefix: str = "c") -> tuple[str, ...]:
    """Channel names of ``count`` channels: ``("value",)``, ``("R", "G", "B")`` or
    ``(prefix + "0", prefix + "1", ...)``.

    >>> default_channels(1), default_channels(3), default_channels(2, "band_")
    (('value',), ('R', 'G', 'B'), ('band_0', 'band_1'))
    """
    if count == 1:
        return ("value",)
    if count == 3:
        return ("R", "G", "B")
    return tuple(f"{prefix}{k}" for k in range(count))


class ReferenceBRDF:
    """Base of every reference BRDF (module docstring).

    A subclass sets :attr:`channels` and implements :meth:`core`; it may set
    :attr:`error` (the exception of its bad-input messages), :attr:`label` (the name in
    them) and :attr:`chunk`.
    """

    #: Channel names; ``len(channels)`` is C.
    channels: tuple[str, ...] = ("value",)
    #: Exception raised for directions of the wrong shape.
    error: type[KesbrdfError] = KesbrdfError
    #: Pairs per call of :meth:`core`.
    chunk: int = EVAL_CHUNK

    @property
    def label(self) -> str:
        """The reference's name in error messages (the class name)."""
        return type(self).__name__

    def core(self, wi: np.ndarray, wr: np.ndarray) -> np.ndarray:
        """f_r in 1/sr, shape (n, C), of unit rows ``wi``, ``wr`` (n, 3), all above the horizon."""
        raise NotImplementedError(f"{self.label} does not implement core()")

    def __call__(self, wi, wr) -> np.ndarray:
        """f_r(wi, wr) in 1/sr for ``wi`` (to the light) and ``wr`` (to the viewer).

        Parameters
        ----------
        wi, wr : array_like, shape (..., 3)
            Directions in the fabric frame (x = warp, y = weft, z = normal); leading axes
            broadcast.

        Returns
        -------
        ndarray, shape broadcast(wi, wr)[:-1] + (C,)
            0 where either direction is at or below the horizon, NaN where an input
            component is not finite.
        """
        wi = np.asarray(wi, dtype=float)
        wr = np.asarray(wr, dtype=float)
        if wi.ndim == 0 or wr.ndim == 0 or wi.shape[-1] != 3 or wr.shape[-1] != 3:
            raise self.error(
                f"{self.label}: expected direction arrays of shape (..., 3), got {np.shape(wi)} and {np.shape(wr)}"
            )
        return evaluate_pairs(lambda a, b, _mapping: self.core(a, b), wi, wr, len(self.channels), "", self.chunk)
