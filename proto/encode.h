/* encode.h: mesh encoders for the wire (binary PLY, OBJ text, binary STL, Draco, glTF
 * binary with KHR_draco_mesh_compression) and the Draco decoder that tests and fuzzers check them with.
 *
 * Every encoder takes an iso_mesh (core/mesh/mesh.h) and returns a malloc'd byte buffer that the
 * caller frees with free(). Functions return 0 or a negative ISO_E_* code (core/base/base.h) and
 * fill `err` when it is not NULL; on error *out is NULL and *out_size 0. NULL mesh, out or
 * out_size pointers are caller bugs (asserted). A mesh whose indices are out of range, whose
 * counts do not fit uint32, or (for Draco and glb) whose positions are not finite is refused
 * with ISO_E_ARGUMENT instead of producing a broken file. */
#ifndef PROTO_ENCODE_H
#define PROTO_ENCODE_H

#include <stddef.h>
#include <stdint.h>

/* core/'s headers have no C++ guards of their own; the Draco shim includes them through
 * this header. */
#ifdef __cplusplus
extern "C" {
#endif

#include "base/base.h"
#include "mesh/mesh.h"

/* Ranges of the options, for request validation in callers. */
enum {
    PROTO_POSITION_BITS_MIN = 8,
    PROTO_POSITION_BITS_MAX = 24,
    PROTO_POSITION_BITS_DEFAULT = 14,
    PROTO_NORMAL_BITS_MIN = 6,
    PROTO_NORMAL_BITS_MAX = 16,
    PROTO_NORMAL_BITS_DEFAULT = 10,
    PROTO_DRACO_SPEED_AUTO = -1, /* proto_draco_auto_speed picks by triangle count */
    PROTO_DRACO_SPEED_MIN = 0,
    PROTO_DRACO_SPEED_MAX = 10,
    PROTO_DRACO_SPEED_DEFAULT = PROTO_DRACO_SPEED_AUTO
};

/* Draco options (PLY and OBJ are lossless and take none). */
typedef struct proto_encode_options {
    /* Position quantization bits: the mesh's bounding cube (its largest extent) is cut into
     * 2^bits - 1 steps, so a position moves by at most half a step per axis. */
    int position_bits;
    /* Normal quantization bits (octahedral), used only when the mesh has normals. */
    int normal_bits;
    /* Draco encoding and decoding speed, 0 (smallest) .. 10 (fastest), or
     * PROTO_DRACO_SPEED_AUTO; Draco's compression level is 10 - speed. Below 10 Draco uses
     * edgebreaker, which reorders vertices and triangles; 10 is the sequential coder with
     * compressed connectivity: order kept, about twice the bytes of 8, 2.5x faster. */
    int speed;
    /* Threads for the sequential coder (speed 10): 0 = all cores, 1 = one. With two or more
     * it encodes the connectivity and the attributes on two threads and joins them into
     * the stream one thread writes, byte for byte. Other speeds use one thread. */
    int threads;
} proto_encode_options;

/* Fills the defaults: 14 position bits, 10 normal bits, speed auto. */
void proto_encode_options_init(proto_encode_options *opt);

/* The speed PROTO_DRACO_SPEED_AUTO encodes a mesh of `triangles` with: 8 up to
 * PROTO_DRACO_AUTO_SEQUENTIAL triangles, 10 above. Speed 8 is smaller than 5, 6 and 7 and
 * faster to encode and decode than all three; the slower speeds save a few percent of the
 * bytes for several times the time; 10 costs about twice the bytes and encodes 2-2.6x
 * faster, so only a mesh too large to encode at 8 within an interactive request's budget
 * gets it (docs/performance.md has the measurements). */
#define PROTO_DRACO_AUTO_SEQUENTIAL 200000
int proto_draco_auto_speed(size_t triangles);

/* Checks that a mesh can be encoded: counts fit uint32 (PLY and glTF indices), every index
 * is below vertex_count and, when `finite` is set, every position is finite (Draco's
 * quantization grid and glTF's min/max need that). O(V + T). Returns 0 or ISO_E_ARGUMENT /
 * ISO_E_LIMIT. Safe on any mesh whose arrays hold their counts. */
int proto_mesh_check(const iso_mesh *mesh, int finite, iso_error *err);

/* proto_mesh_check in its two parts: the counts (O(1)), then the indices and values
 * (O(V + T)), for an encoder that scans the data on a thread that would otherwise wait. */
int proto_mesh_check_counts(const iso_mesh *mesh, iso_error *err);
int proto_mesh_check_data(const iso_mesh *mesh, int finite, iso_error *err);

/* Binary little-endian PLY: `element vertex N` with float x, y, z (and nx, ny, nz when the
 * mesh has normals), `element face T` with `property list uchar uint vertex_indices`.
 * Lossless, keeps order. Size: header + N * (12 or 24) + T * 13 bytes. */
int proto_encode_ply(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                     iso_error *err);

/* Wavefront OBJ text: `v` lines (floats printed with 9 significant digits, which round-trip
 * float32), `vn` lines when the mesh has normals, `f` lines with 1-based indices
 * (`f a//a b//b c//c` with normals). Lossless, keeps order. */
int proto_encode_obj(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                     iso_error *err);

/* Binary STL, for 3D printing: an 80-byte header (not starting with "solid"), a uint32
 * triangle count, then per triangle its unit facet normal from the winding, its three
 * corners and a zero uint16: 84 + 50 T bytes, little endian. Lossless positions; the
 * vertices are repeated per triangle, as STL has no index. Print a closed mesh (cap). */
int proto_encode_stl(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                     iso_error *err);

/* A Draco mesh bitstream (libdraco 1.5.5, readable by draco3d 1.5.x). opt NULL means the
 * defaults; options out of range give ISO_E_ARGUMENT; speed auto is resolved on the count
 * of triangles left once degenerate ones are dropped. Triangles with a repeated index and
 * vertices no other triangle uses are dropped, non-manifold vertices may be split, and
 * order changes below speed 10 (see proto_encode_options). A mesh left with no triangles,
 * which Draco's mesh encoders refuse, becomes a tiny stream (22 bytes) that decodes to an
 * empty mesh: a POSITION attribute, no points, no faces (see draco_shim.cc). O(T); the
 * cost per triangle at each speed is in docs/performance.md. */
int proto_encode_draco(const iso_mesh *mesh, const proto_encode_options *opt,
                       unsigned char **out, size_t *out_size, iso_error *err);

/* glTF 2.0 binary: one scene, one node, one mesh with one triangle primitive compressed with
 * KHR_draco_mesh_compression (required), POSITION accessor with the decoded min/max, NORMAL
 * when the mesh has normals. A mesh with no triangles gives a valid glb whose scene has no
 * nodes (glTF forbids accessors with count 0) and no BIN chunk. */
int proto_encode_glb(const iso_mesh *mesh, const proto_encode_options *opt,
                     unsigned char **out, size_t *out_size, iso_error *err);

/* glTF 2.0 binary that any glTF reader opens, no extension used or required: POSITION as
 * float VEC3 (with its min and max), NORMAL likewise when the mesh has normals, indices as
 * uint32, each in its own buffer view; the mesh's own vertices and triangles in order,
 * lossless. Size: about 1.2 KB + 24 V (12 without normals) + 12 T bytes. A mesh with no
 * triangles gives the same empty glb as proto_encode_glb. O(V + T). */
int proto_encode_glb_plain(const iso_mesh *mesh, unsigned char **out, size_t *out_size,
                           iso_error *err);

/* glTF 2.0 binary for a fast decode: one scene, one node, one triangle primitive whose
 * buffer views are compressed with meshoptimizer's codecs (EXT_meshopt_compression,
 * required) over quantized attributes (KHR_mesh_quantization, required): positions as
 * uint16 on the bounding cube's qp-bit grid (like Draco's, the node's translation and
 * scale give world units back; float positions above 16 bits), normals as normalized
 * int8 (qn <= 8) or int16 rounded to qn bits; indices uint16 when the vertices allow,
 * else uint32. Vertex order and counts are kept, triangles too, each perhaps starting at
 * another corner (the index codec rotates them; the winding stays). A mesh with no triangles
 * gives the same empty glb as proto_encode_glb. O(V + T), single pass per stream. */
int proto_encode_glb_meshopt(const iso_mesh *mesh, const proto_encode_options *opt,
                             unsigned char **out, size_t *out_size, iso_error *err);

/* Several meshes in one glTF binary (a segmentation's segments): one part per mesh, each a
 * glb of proto_encode_glb or proto_encode_glb_meshopt (all parts of one kind), joined
 * (glb_scene.c): one node per part named after it (its number in the node's extras as
 * "segment"), its mesh encoded as in its own glb, a material per part whose
 * baseColorFactor is its colour in linear light; a part without triangles gives a node
 * without a mesh. The scene's nodes are in the parts' order. O(bytes). Returns 0,
 * ISO_E_NOMEM or ISO_E_LIMIT (over glTF's 4 GiB). */
typedef struct proto_scene_part {
    const unsigned char *glb;
    size_t size;
    const char *name;
    uint32_t number;
    float color[3];   /* sRGB, 0..1 */
} proto_scene_part;
int proto_glb_scene(const proto_scene_part *parts, size_t count, unsigned char **out, size_t *out_size,
                    iso_error *err);

/* proto_encode_glb_meshopt for a request pipeline (pipeline.c), with its steps overlapped
 * on two threads: the normals made first by a callback (the index view, which does not
 * read them, is numbered and coded beside them), and the gzip member made too, each
 * stream deflated on the thread that coded it as soon as it is coded; the glb's bytes are
 * proto_encode_glb_meshopt's. */
typedef struct proto_meshopt_run {
    /* NULL: the mesh has its normals or none. Else called once, before the normals are
     * read, on `threads` threads (1 while the other codes the indices); it sets the mesh's
     * normals (the mesh given to the encoder) or fails with its error. */
    int (*make_normals)(void *context, int threads, iso_error *err);
    void *context;
    int gzip;                    /* 1: also the gzip member of the glb (proto_gzip's form) */
    unsigned char *gzip_bytes;   /* out: that member (malloc'd), NULL without gzip */
    size_t gzip_size;
    /* out, iso_clock_ms() when the normals were made, the glb done, the gzip member done:
     * the steps end in this order, so their differences add up to the call's time. */
    double normals_done, glb_done, gzip_done;
} proto_meshopt_run;

int proto_encode_glb_meshopt_run(const iso_mesh *mesh, const proto_encode_options *opt,
                                 proto_meshopt_run *run, unsigned char **out, size_t *out_size,
                                 iso_error *err);

/* 1 when the n floats at v are all finite (a pass without a branch per value). */
int proto_floats_finite(const float *v, size_t n);

/* One gzip member (RFC 1952) holding `in`, deflated by gzip.c's greedy matcher (about as
 * small as zlib's fastest level, several times as fast), for HTTP's Content-Encoding: gzip.
 * Returns 0 or ISO_E_NOMEM / ISO_E_LIMIT (over 4 GiB). */
int proto_gzip(const unsigned char *in, size_t size, unsigned char **out, size_t *out_size,
               iso_error *err);

/* A piece of a buffer to gzip: it ends at `end` (the last piece ends at the buffer's end,
 * whatever `end` says); `huffman`: entropy coding alone (a table per 64 KB, gzip.c), for
 * bytes with few repeats, such as meshopt's vertex streams: about as small there as
 * matching and about 4 times as fast; else matches (gzip.c's greedy LZ77). */
typedef struct proto_gzip_piece {
    size_t end;
    int huffman;
} proto_gzip_piece;
#define PROTO_GZIP_PIECES_MAX 4

/* proto_gzip with the buffer cut into `count` (1..PROTO_GZIP_PIECES_MAX) consecutive
 * pieces deflated independently (a Huffman-only one in parts of 256 KB or more), on up
 * to `threads` threads (0: all cores) taking the parts as they come free, joined into one
 * gzip member. Same errors. */
int proto_gzip_pieces(const unsigned char *in, size_t size, const proto_gzip_piece *pieces, int count,
                      int threads, unsigned char **out, size_t *out_size, iso_error *err);

/* The pieces in which to gzip a glb made by proto_encode_glb_meshopt: the container and
 * the vertex streams (Huffman only), the index stream's header and codes (matches, which
 * find the index codec's repeats), then its data (Huffman only: matches would save 10%
 * more of it for 3 times the time). Fills pieces[0..2] and returns 3; 1 (the whole) if
 * the bytes are not such a glb. */
int proto_glb_meshopt_gzip_pieces(const unsigned char *glb, size_t size,
                                  proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX]);

/* Decodes a Draco mesh bitstream into `out`, which is initialised by the call: on success it
 * owns the positions, the normals when the stream has a 3-component NORMAL attribute, and
 * the triangles (free with iso_mesh_free); on error it is left empty. Safe on untrusted
 * input: garbage and truncated data give ISO_E_FORMAT, never a crash (as far as libdraco
 * itself is safe). Cost: Draco's decode plus one pass over the points and faces. */
int proto_draco_decode(const void *data, size_t size, iso_mesh *out, iso_error *err);

#ifdef __cplusplus
}
#endif

#endif
