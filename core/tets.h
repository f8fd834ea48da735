/* tets.h: polygonizing one node's trilinear with marching tetrahedra under a Lemma 2 bound
 * (Elber and Malzbender, Section 3).
 *
 * The node's box is cut into s_x * s_y * s_z equal sub-boxes, each into six Kuhn
 * tetrahedra; on each tetrahedron the trilinear T is replaced by the linear function
 * through its vertices, whose level set is exactly one triangle or quad. Subdivision
 * doubles per axis until iso_tri_kuhn_bound of every sub-box fits the budget, and gives up
 * when sub-boxes would average under eight data cells: six tetrahedra give about twice the
 * triangles of one marching cube, so marching the cells themselves is then cheaper. Every point p of the output then has |T(p) - level| <= delta,
 * the largest bound met. */
#ifndef ISO_TETS_H
#define ISO_TETS_H

#include "mesh.h"
#include "tree.h"

/* c: T's corner values (corner order of trilinear.h) on box. Appends the triangles to soup
 * in index space. Returns 1 and sets *delta when the bound fit the budget, 0 when it did
 * not fit before sub-boxes got that small (nothing appended: the caller descends instead),
 * ISO_E_NOMEM on allocation failure. *sub_boxes gets the sub-box count examined. */
int iso_tets_polygonize(const double c[8], const iso_box *box, double level, double budget,
                        iso_mesh *soup, double *delta, size_t *sub_boxes);

#endif
