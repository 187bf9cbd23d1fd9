"""Dressing simulation (the paper's application): cloth draped with newton's XPBD.

* :mod:`kesbrdf.cloth.drape`: :func:`simulate_drape` (resumable, atomic frames);
* :mod:`kesbrdf.cloth.scenes`: the satin sheet, the skirt, the sphere and the dress form;
* :mod:`kesbrdf.cloth.grid`: a cloth piece (particles, masses, springs; straight or bias grain);
* :mod:`kesbrdf.cloth.pattern`: the six-gore skirt cut from flat pattern panels and sewn
  (its centre front on the bias);
* :mod:`kesbrdf.cloth.render_mesh`: the garment as rendered (seams welded, Loop-subdivided);
* :mod:`kesbrdf.cloth.mannequin`: the smooth procedural mannequin (a triangle-mesh collider);
* :mod:`kesbrdf.cloth.ply`: binary PLY meshes (x y z nx ny nz u v) for Mitsuba 3.

Only :mod:`~kesbrdf.cloth.drape` needs the optional ``newton`` / ``warp-lang``
packages (``pip install kesbrdf[cloth]``), and only once a simulation starts.
"""

from kesbrdf.cloth.drape import SCENES, DrapeError, DrapeParameters, simulate_drape
from kesbrdf.cloth.ply import PlyMesh, read_ply, vertex_normals, write_ply

__all__ = ["SCENES", "DrapeError", "DrapeParameters", "simulate_drape", "PlyMesh", "read_ply", "write_ply",
           "vertex_normals"]
