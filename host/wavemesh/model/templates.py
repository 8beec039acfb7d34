"""The complete template set and the template look-up table, generated from
:mod:`wavemesh.model.template_forms` by the generating functions g_ijk (eq. 3.28-3.30).

Generating functions act on the nine sites (row r, column c, both 0..2)::

    g_h: (r, c) -> (r, 2 - c)        horizontal flip (mirror left-right)
    g_v: (r, c) -> (2 - r, c)        vertical flip (mirror top-bottom)
    g_r: (r, c) -> (c, 2 - r)        rotation by a quarter turn
    g_ijk = g_h^i o g_v^j o g_r^k    (g_r applied first)

The eight g_ijk are the eight symmetries of the square.  The closure of the 13
forms under them holds every variant; the look-up table picks, for each block
label and set of split sides, the one variant that

- has a vertex on exactly the split side midpoints (vertex compatibility, 3.5.4)
  and on the centre exactly for D;
- for V/v (H/h) has the vertical edge 1-7 (horizontal edge 3-5);
- keeps the label's diagonal direction: every slanted edge bottom-left to
  top-right for a basic label (F, V, H), top-left to bottom-right for a dual
  (f, v, h).

Cases the paper's forms do not cover directly resolve as follows (docs/model.md):
an F block with two opposite sides split takes pi_v or pi_h (the block is then
vertical or horizontal in all but name), with three sides split pi1, with all
four pi2 along the vertical axis; with two adjacent sides split it takes pi4,
whose joined midpoints cut off the corner between them, whatever its diagonal
was.  The generator checks that every case has exactly one match.

Labels are 3-bit codes ``kind << 1 | dual`` (F f V v H h D = 0..6); the split
mask has bit 0 top (site 1), bit 1 left (3), bit 2 right (5), bit 3 bottom (7).
The look-up table index is ``label << 4 | mask``.
"""

from __future__ import annotations

import functools

from wavemesh.model import template_forms
from wavemesh.record import record

LABELS = "FfVvHhD"  # code -> letter
KIND_FLAT, KIND_VERTICAL, KIND_HORIZONTAL, KIND_DIAGONAL = 0, 1, 2, 3
SIDE_TOP, SIDE_LEFT, SIDE_RIGHT, SIDE_BOTTOM = 1, 2, 4, 8
SIDE_SITES = ((SIDE_TOP, 1), (SIDE_LEFT, 3), (SIDE_RIGHT, 5), (SIDE_BOTTOM, 7))
CENTRE_SITE = 4
LUT_SIZE = 128  # 8 label codes (7 used) x 16 masks
LUT_INVALID = 0xFF  # a label/mask pair that cannot occur (V without top and bottom split, ...)
MAX_TRIANGLES = 8  # most triangles in one template (pi9)

GEN_NAMES = ("g000", "g001", "g010", "g011", "g100", "g101", "g110", "g111")


def label_code(kind: int, dual: bool) -> int:
    return kind << 1 | int(dual and kind != KIND_DIAGONAL)


def own_sides(label: int) -> int:
    """Side midpoints a block's own label puts on its sides (pi_v: top and bottom, pi_h: left and right)."""
    kind = label >> 1
    if kind == KIND_VERTICAL:
        return SIDE_TOP | SIDE_BOTTOM
    if kind == KIND_HORIZONTAL:
        return SIDE_LEFT | SIDE_RIGHT
    return 0


_RC = tuple(divmod(s, 3) for s in range(9))  # site -> (row, column), looked up (the set is built per process)


def site_rc(s: int) -> tuple[int, int]:
    return _RC[s]


def _g(i: int, j: int, k: int, s: int) -> int:
    r, c = site_rc(s)
    if k:
        r, c = c, 2 - r
    if j:
        r = 2 - r
    if i:
        c = 2 - c
    return 3 * r + c


def ccw(tri) -> tuple[int, int, int]:
    """The triangle's sites in counter-clockwise order (x = column, y = row), starting at the smallest."""
    a, b, c = sorted(tri)
    (ra, ca), (rb, cb), (rc, cc) = _RC[a], _RC[b], _RC[c]
    area2 = (cb - ca) * (rc - ra) - (cc - ca) * (rb - ra)
    if area2 == 0:
        raise ValueError(f"degenerate template triangle {tri}")
    return (a, b, c) if area2 > 0 else (a, c, b)


@record(frozen=True)
class Template:
    """One template of the complete set."""

    id: int
    name: str  # e.g. "pi3.g101": generated from form pi3 by g_101
    form: str
    gen: str
    triangles: tuple[tuple[int, int, int], ...]  # counter-clockwise site triples, sorted

    @property
    def sites(self) -> frozenset[int]:
        return frozenset(s for t in self.triangles for s in t)

    @property
    def sides(self) -> int:
        return sum(bit for bit, site in SIDE_SITES if site in self.sites)


def _key(tris) -> frozenset:
    return frozenset(frozenset(t) for t in tris)


def _edges(tris) -> set[frozenset]:
    return {frozenset((t[i], t[(i + 1) % 3])) for t in tris for i in range(3)}


def _diag_type(tris) -> str:
    """'basic' if every slanted edge runs bottom-left to top-right, 'dual' if top-left to bottom-right."""
    signs = set()
    for e in _edges(tris):
        (r0, c0), (r1, c1) = (_RC[s] for s in e)
        if r0 != r1 and c0 != c1:
            signs.add((r1 - r0) * (c1 - c0) > 0)
    if signs == {False}:
        return "basic"
    if signs == {True}:
        return "dual"
    return "mixed"


def _axis(tris) -> str | None:
    edges = _edges(tris)
    if frozenset((1, 7)) in edges:
        return "v"
    if frozenset((3, 5)) in edges:
        return "h"
    return None


@functools.cache
def _closure() -> tuple[tuple[str, str, tuple], ...]:
    """Every distinct triangulation g_ijk(form): (form, gen, ccw triangles).

    A triangulation reachable several ways is named by the lowest generator, then the
    earliest form, so each basic template and form is named after itself (pi_h.g000,
    not pi_v.g011)."""
    forms = {**{k: v[1] for k, v in template_forms.BASIC.items()},
             **{k: v[1] for k, v in template_forms.FUNDAMENTAL.items()}}
    seen: dict[frozenset, tuple] = {}
    for gi, gname in enumerate(GEN_NAMES):
        g = [_g((gi >> 2) & 1, (gi >> 1) & 1, gi & 1, s) for s in range(9)]  # g_ijk as a site table
        for form, tris in forms.items():
            out = tuple(sorted(ccw(tuple(g[s] for s in t)) for t in tris))
            key = _key(out)
            if key not in seen:
                seen[key] = (form, gname, out)
    return tuple(seen.values())


def _facts(tris) -> tuple[bool, int, str | None, str]:
    """What the look-up table's predicates (_wanted) ask of a triangulation, worked out once per closure
    member rather than once per label and mask (a short run paid ~15 ms for that): a vertex on the
    centre, the split sides, the axis edge, the diagonals' direction."""
    sites = {s for t in tris for s in t}
    return CENTRE_SITE in sites, _sides(sites), _axis(tris), _diag_type(tris)


def _wanted(label: int, mask: int):
    """The predicate on a triangulation's _facts for a block with this label and split mask, or None."""
    kind, dual = label >> 1, bool(label & 1)
    if kind == KIND_DIAGONAL:
        if dual:
            return None
        return lambda centre, sides, _axis, _diag: centre and sides == mask
    need = own_sides(label)
    if mask & need != need:
        return None
    tb = mask & (SIDE_TOP | SIDE_BOTTOM) == SIDE_TOP | SIDE_BOTTOM
    lr = mask & (SIDE_LEFT | SIDE_RIGHT) == SIDE_LEFT | SIDE_RIGHT
    plain = lambda centre, sides, _axis, _diag: not centre and sides == mask  # noqa: E731
    if kind == KIND_FLAT and bin(mask).count("1") == 2 and not tb and not lr:
        return plain  # pi4: two adjacent sides, whatever the diagonal
    if kind == KIND_VERTICAL or (kind == KIND_FLAT and tb):
        axis = "v"
    elif kind == KIND_HORIZONTAL or (kind == KIND_FLAT and lr):
        axis = "h"
    else:
        axis = None
    diag = "dual" if dual else "basic"
    return lambda centre, sides, ax, dg: plain(centre, sides, ax, dg) and ax == axis and dg == diag


def _sides(sites) -> int:
    return sum(bit for bit, site in SIDE_SITES if site in sites)


@record(frozen=True)
class TemplateSet:
    templates: tuple[Template, ...]
    lut: tuple[int, ...]  # LUT_SIZE entries: label << 4 | mask -> template id or LUT_INVALID

    def lookup(self, label: int, mask: int) -> Template:
        tid = self.lut[label << 4 | mask]
        if tid == LUT_INVALID:
            raise ValueError(f"label {LABELS[label]} cannot have split mask {mask:04b}")
        return self.templates[tid]


@functools.cache
def template_set() -> TemplateSet:
    """Build the complete set: the templates the look-up table uses, in generator order."""
    closure = _closure()
    facts = [_facts(tris) for _, _, tris in closure]
    by_sides: dict[int, list[int]] = {}  # every predicate asks for sides == mask: only those are tried
    for n, f in enumerate(facts):
        by_sides.setdefault(f[1], []).append(n)
    choice: dict[int, int] = {}  # lut index -> closure index
    for label in range(len(LABELS)):
        for mask in range(16):
            pred = _wanted(label, mask)
            if pred is None:
                continue
            hits = [n for n in by_sides.get(mask, ()) if pred(*facts[n])]
            if len(hits) != 1:
                raise AssertionError(f"label {LABELS[label]} mask {mask:04b}: {len(hits)} templates match")
            choice[label << 4 | mask] = hits[0]
    used = sorted(set(choice.values()))
    ids = {n: i for i, n in enumerate(used)}
    templates = tuple(
        Template(ids[n], f"{closure[n][0]}.{closure[n][1]}", closure[n][0], closure[n][1], closure[n][2])
        for n in used
    )
    lut = tuple(ids[choice[i]] if i in choice else LUT_INVALID for i in range(LUT_SIZE))
    return TemplateSet(templates, lut)


def apply_generator(gen: str, tris) -> tuple[tuple[int, int, int], ...]:
    """g_ijk applied to a list of site triangles (for tests and docs)."""
    i, j, k = (int(ch) for ch in gen[1:])
    return tuple(sorted(ccw(tuple(_g(i, j, k, s) for s in t)) for t in tris))


def same_triangulation(a, b) -> bool:
    return _key(a) == _key(b)
