"""The source of truth of the template set: 4 basic templates and 9 fundamental forms.

Everything else about templates (the complete set, the look-up table from a
block's label and split sides to a template, the Verilog ROM include, the C
header, docs/templates.md) is generated from the data in this file by
:mod:`wavemesh.model.templates`.  Edit here, nowhere else.

A template triangulates one block of the coarsest level.  Its vertices are taken
from nine sites, numbered row by row (row 0 at the top, y grows downwards as in
an image; x grows to the right)::

      0 ----- 1 ----- 2        corners 0 2 6 8
      |               |        side midpoints 1 (top) 3 (left) 5 (right) 7 (bottom)
      3       4       5        centre 4
      |               |
      6 ----- 7 ----- 8

Triangles are listed as site triples in any order; the generator orients them
counter-clockwise.  The dissertation's figures are lost; these forms are our
reconstruction from its text (docs/model.md, "Templates", says why each one).

Diagonal direction: pi_f cuts the block along 6-2 (bottom-left to top-right).
With d1 ~ df/dx and d2 ~ df/dy, d1*d2 >= 0 means the height rises towards the
bottom-right corner, so level contours run from bottom-left to top-right and
the 6-2 diagonal follows them (fig. 3.12).  Every basic template and form keeps
that direction; duals are their vertical flips (eq. 3.26).
"""

# name -> (description, triangles as site triples)
BASIC = {
    # 0---2      flat: one diagonal
    # | / |
    # 6---8
    "pi_f": ("flat: one diagonal 6-2", [(0, 2, 6), (2, 8, 6)]),
    # 0-1-2      vertical: edge 1-7, each half cut parallel to pi_f's diagonal
    # |/|/|
    # 6-7-8
    "pi_v": ("vertical: edge 1-7, halves cut by 6-1 and 7-2", [(0, 1, 6), (1, 7, 6), (1, 2, 7), (2, 8, 7)]),
    # pi_h = g_v(g_r(pi_v)) (eq. 3.22); kept as data because it is a basic template.
    "pi_h": ("horizontal: edge 3-5, halves cut by 3-2 and 6-5", [(0, 2, 3), (2, 5, 3), (3, 5, 6), (5, 8, 6)]),
    # 0---2      diagonal: both diagonals through the centre (self-dual)
    # |\ /|
    # | 4 |
    # |/ \|
    # 6---8
    "pi_d": ("diagonal: both diagonals through centre 4", [(0, 2, 4), (2, 8, 4), (8, 6, 4), (6, 0, 4)]),
}

FUNDAMENTAL = {
    # pi_v with its left side split; the left half keeps the 6-1 diagonal (fig. 3.14(c)).
    "pi1": ("pi_v + left midpoint 3", [(0, 1, 3), (3, 1, 6), (1, 7, 6), (1, 2, 7), (2, 8, 7)]),
    # pi_v with both other sides split.
    "pi2": (
        "pi_v + left 3 and right 5",
        [(0, 1, 3), (3, 1, 6), (1, 7, 6), (1, 2, 7), (2, 5, 7), (5, 8, 7)],
    ),
    # pi_f with one side split: the midpoint joins the opposite corner.
    "pi3": ("pi_f + top midpoint 1", [(0, 1, 6), (1, 2, 6), (2, 8, 6)]),
    # pi_f with two adjacent sides split: the two midpoints are joined (fig. 3.17), cutting off the
    # corner between them; the rest fans from the opposite corner 6.  Symmetric about the 6-2 diagonal.
    "pi4": ("pi_f + top 1 and right 5, joined", [(0, 1, 6), (1, 5, 6), (1, 2, 5), (5, 8, 6)]),
    # pi_d with 1, 2 adjacent, 2 opposite, 3 and 4 sides split; each midpoint joins the centre.
    "pi5": ("pi_d + top 1", [(0, 1, 4), (1, 2, 4), (2, 8, 4), (8, 6, 4), (6, 0, 4)]),
    "pi6": ("pi_d + top 1, right 5", [(0, 1, 4), (1, 2, 4), (2, 5, 4), (5, 8, 4), (8, 6, 4), (6, 0, 4)]),
    "pi7": ("pi_d + top 1, bottom 7", [(0, 1, 4), (1, 2, 4), (2, 8, 4), (8, 7, 4), (7, 6, 4), (6, 0, 4)]),
    "pi8": (
        "pi_d + top 1, right 5, bottom 7",
        [(0, 1, 4), (1, 2, 4), (2, 5, 4), (5, 8, 4), (8, 7, 4), (7, 6, 4), (6, 0, 4)],
    ),
    "pi9": (
        "pi_d + all four midpoints",
        [(0, 1, 4), (1, 2, 4), (2, 5, 4), (5, 8, 4), (8, 7, 4), (7, 6, 4), (6, 3, 4), (3, 0, 4)],
    ),
}
