"""Models layer: checks of a mesh before the FE basis is built and M, K are assembled.

:func:`check_assembly` estimates the memory that building the scikit-fem basis and assembling the
mass and stiffness matrices take and refuses a mesh that does not fit (naming elements, local
DOFs, GiB and the fix) before numpy fails deep inside the assembly. :func:`check_element_measures`
names a degenerate element (zero area or volume), whose singular element map would otherwise show
up as an "overflow" of the assembled matrices.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import skfem

from ..solvers.checks import InputValueError, check_memory

__all__ = ["ASSEMBLY_BLOCK_BYTES", "assembly_block", "assembly_memory", "check_assembly", "check_element_measures", "outward_normal"]

#: Bytes per element and per pair of its local DOFs that assembling M and K takes: scikit-fem's
#: COO triplets (an 8-byte value and two 8-byte indices) for each of the two matrices, twice for
#: the conversion to CSR.
_ASSEMBLY_BYTES_PER_PAIR = 2 * 24 * 2


#: scikit-fem's work (:func:`assembly_memory` of one block of elements) above which
#: :func:`femodes.fe.assembly.assemble_blocks` assembles a mesh in blocks of elements. The estimate
#: is about twice the measured peak, so a block takes about 0.5 GiB: large enough that scikit-fem's
#: per-call overhead (a Python loop over the pairs of local functions) stays small.
ASSEMBLY_BLOCK_BYTES = 2**30

#: Bytes per pair of local DOFs of an element that the blocks of one matrix keep until they are
#: summed: the COO triplets of each block (an 8-byte value and two 4-byte indices), counted once
#: per element (a bound: pairs shared between elements of a block are stored once).
_BLOCK_TRIPLET_BYTES = 16


def _per_element(mesh: Any, element: Any) -> tuple[int, float]:
    """(local DOFs, bytes of scikit-fem's work per element) of assembling M and K."""
    nb = int(np.asarray(element.doflocs).shape[0])
    dim = int(np.asarray(mesh.p).shape[0])
    try:  # scikit-fem's default rule: exact for products of two basis functions
        n_qp = int(np.asarray(skfem.quadrature.get_quadrature(mesh.refdom, 2 * element.maxdeg)[1]).size)
    except Exception:  # noqa: BLE001 - an element without maxdeg or an unknown domain: a generous count
        n_qp = 27
    hessians = dim * dim if "Hermite" in type(element).__name__ else 0  # second derivatives: beams only
    per_function = n_qp * 8 * dim * (1 + dim + hessians)  # value and gradient of each component
    return nb, float(nb * nb * _ASSEMBLY_BYTES_PER_PAIR + nb * per_function)


def assembly_block(mesh: Any, element: Any) -> int:
    """Elements per block of :func:`femodes.fe.assembly.assemble_blocks`: all of them when the
    whole mesh's work fits in :data:`ASSEMBLY_BLOCK_BYTES`, else as many as fit (at least 1)."""
    return max(1, int(ASSEMBLY_BLOCK_BYTES // _per_element(mesh, element)[1]))


def assembly_memory(mesh: Any, element: Any) -> float:
    """Bytes that building the basis and assembling M and K of ``mesh`` with ``element`` allocate,
    estimated from the counts of elements, local DOFs and quadrature points before anything is
    built: the COO triplets (:data:`_ASSEMBLY_BYTES_PER_PAIR`) and the basis' values and
    gradients (and second derivatives, Hermite beams) of every local function at every quadrature
    point of scikit-fem's default rule: 0.9-1.9 times the tracemalloc peak of ``fm.solid`` measured on
    P1/P2 triangles and tetrahedra and Q1/Q2 hexahedra (tests/test_safeguards.py). A mesh
    assembled in blocks (:func:`assembly_block`) takes one block's work plus the triplets its
    blocks keep (:data:`_BLOCK_TRIPLET_BYTES`) for the two matrices."""
    n_el = int(np.asarray(mesh.t).shape[1])
    nb, per_element = _per_element(mesh, element)
    block = assembly_block(mesh, element)
    if block >= n_el:
        return float(n_el) * per_element
    return float(block) * per_element + 2.0 * n_el * nb * nb * _BLOCK_TRIPLET_BYTES


def check_assembly(mesh: Any, element: Any, fix: str = "use a coarser mesh") -> None:
    """ValueError when :func:`assembly_memory` exceeds the memory available, before anything is built."""
    n_el, nb = int(np.asarray(mesh.t).shape[1]), int(np.asarray(element.doflocs).shape[0])
    check_memory(assembly_memory(mesh, element), f"assembling M and K on {n_el} elements of {nb} DOFs each",
                 fix)


def check_element_measures(mesh: Any) -> None:
    """ValueError naming the first degenerate element of a 2-D or 3-D mesh (zero or non-finite
    area or volume: collinear or coplanar vertices). Measures from the mesh's geometry map at a
    few reference points per element; zero means below 1e-12 of the median element's measure,
    the data's own scale, so a mesh in any length unit passes."""
    dim = int(np.asarray(mesh.p).shape[0])
    X, W = skfem.quadrature.get_quadrature(mesh.refdom, 2)
    with np.errstate(all="ignore"):
        measure = np.abs(np.asarray(mesh.mapping().detDF(X))) @ np.asarray(W)
    ok = np.isfinite(measure)
    ref = float(np.median(measure[ok])) if ok.any() else 0.0
    bad = np.flatnonzero(~ok | (measure <= 1e-12 * ref))
    if bad.size:
        i = int(bad[0])
        verts = np.asarray(mesh.t[:, i])
        coords = ", ".join("(" + ", ".join(f"{v:.6g}" for v in mesh.p[:, j]) + ")" for j in verts)
        what = "area" if dim == 2 else "volume"
        raise InputValueError(f"mesh element {i} has zero {what} (vertices {verts.tolist()} at {coords} are "
                         f"{'collinear' if dim == 2 else 'coplanar'}; {bad.size} such element{'s' * (bad.size != 1)}); "
                         "remove or repair the degenerate elements of the mesh")
    _check_untangled(mesh, ref)


def _check_untangled(mesh: Any, ref: float) -> None:
    """ValueError naming an element whose map folds over itself (its Jacobian changes sign inside
    it: a quadrilateral or hexahedron with its vertices listed in crossed order), or two elements
    that overlap (on the same side of the edge or face they share: a node moved past its
    neighbour). Both assembled silently, with |det J|: a bow-tie quadrilateral moved w1 by 1.4 %,
    a twisted hexahedron by 1.3 %, a tangled mesh by 1.4-6.9 %. Simplices have a constant
    Jacobian, so only the second test can fail for them; either orientation of an element is
    fine."""
    dim = int(np.asarray(mesh.p).shape[0])
    # Gauss points off the centre (2 x 2 on a quadrilateral), where a bow-tie's Jacobian is zero
    X, _ = skfem.quadrature.get_quadrature(mesh.refdom, 3)
    with np.errstate(all="ignore"):
        try:
            det = np.asarray(mesh.mapping().detDF(X))
        except Exception as exc:  # noqa: BLE001 - scikit-fem's "Zero Jacobian determinant" at one of them
            raise InputValueError("a mesh element folds over itself: its Jacobian vanishes inside it (vertices in "
                                  "crossed order); list each element's vertices in the order of its type (around "
                                  "the edges, as gmsh and meshio number them)") from exc
    tol = 1e-9 * ref
    crossed = np.flatnonzero((det.max(axis=1) > tol) & (det.min(axis=1) < -tol))
    if crossed.size:
        i = int(crossed[0])
        raise InputValueError(f"mesh element {i} folds over itself: its Jacobian changes sign inside it (vertices "
                              f"{np.asarray(mesh.t[:, i]).tolist()} are in crossed order; {crossed.size} such "
                              f"element{'s' * (crossed.size != 1)}); list each element's vertices in the order of its "
                              "type (around the edges, as gmsh and meshio number them)")
    t2f = np.asarray(mesh.f2t)
    inner = np.flatnonzero(np.all(t2f >= 0, axis=0))
    if not inner.size:
        return
    p = np.asarray(mesh.p, dtype=float)
    centre = p[:, np.asarray(mesh.t)].mean(axis=1)                # (dim, n_el)
    f = np.asarray(mesh.facets)[:, inner]
    origin = p[:, f[0]]
    if dim == 2:
        d = p[:, f[1]] - origin
        normal = np.vstack([d[1], -d[0]])
    else:
        normal = np.cross((p[:, f[1]] - origin).T, (p[:, f[2]] - origin).T).T
    side = [np.einsum("ij,ij->j", centre[:, t2f[k, inner]] - origin, normal) for k in (0, 1)]
    height = np.abs(side[0]) + np.abs(side[1])
    overlap = np.flatnonzero((side[0] * side[1] > 0) & (height > 1e-9 * ref))
    if overlap.size:
        j = int(inner[overlap[0]])
        a, b = (int(e) for e in t2f[:, j])
        raise InputValueError(f"mesh elements {a} and {b} overlap: they lie on the same side of the "
                              f"{'edge' if dim == 2 else 'face'} they share (vertices {np.asarray(mesh.facets[:, j]).tolist()}; "
                              f"{overlap.size} such pair{'s' * (overlap.size != 1)}): a node moved past its neighbour; "
                              "repair the mesh")


def outward_normal(mesh: Any, boundary: str) -> np.ndarray | None:
    """Area-weighted mean outward unit normal of the facets of ``mesh.boundaries[boundary]`` (2-D
    edges, 3-D triangles or quadrilaterals), oriented away from the element each facet belongs
    to; ``None`` for line meshes, unknown names or a boundary whose normals cancel (a closed
    surface)."""
    boundaries = getattr(mesh, "boundaries", None) or {}
    facets = boundaries.get(boundary) if isinstance(boundaries, dict) else None
    dim = int(mesh.p.shape[0])
    if facets is None or dim < 2 or len(facets) == 0:
        return None
    facets = np.asarray(facets, dtype=int)
    nodes = mesh.facets[:, facets]                       # (nodes per facet, n_facets)
    p = np.asarray(mesh.p, dtype=float)
    if dim == 2:
        t = p[:, nodes[1]] - p[:, nodes[0]]
        n = np.vstack([t[1], -t[0]])                     # length = edge length
    else:
        n = 0.5 * np.cross((p[:, nodes[1]] - p[:, nodes[0]]).T, (p[:, nodes[2]] - p[:, nodes[0]]).T).T
    inside = p[:, mesh.t[:, mesh.f2t[0, facets]]].mean(axis=1)   # centroid of each facet's element
    centre = p[:, nodes].mean(axis=1)
    n = n * np.sign(np.sum(n * (centre - inside), axis=0))
    total = n.sum(axis=1)
    norm = float(np.linalg.norm(total))
    if norm <= 1e-12 * float(np.sum(np.linalg.norm(n, axis=0))):
        return None
    return total / norm
