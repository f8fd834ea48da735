// draco_shim.cc: the extern "C" bridge to libdraco 1.5.5 (C++): iso_mesh -> Draco bytes and
// back. Every entry point catches all C++ exceptions, so none crosses into C.
#include "draco_shim.h"

#include <draco/attributes/attribute_quantization_transform.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/quantization_utils.h>
#include <draco/core/varint_encoding.h>
#include <draco/mesh/mesh.h>

#include <algorithm>
#include <cassert>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <vector>

extern "C" {
#include "base/base.h"
}

namespace {

// Maps an escaped exception to a status: only an allocation failure has its own code.
int exception_status(iso_error *err, const char *what, int code)
{
    try {
        throw;
    } catch (const std::bad_alloc &) {
        return iso_error_set(err, ISO_E_NOMEM, "draco %s: out of memory", what);
    } catch (const std::exception &e) {
        return iso_error_set(err, code, "draco %s: %s", what, e.what());
    } catch (...) {
        return iso_error_set(err, code, "draco %s: unknown exception", what);
    }
}

int copy_bytes(const char *data, size_t size, unsigned char **out, size_t *out_size, iso_error *err)
{
    // malloc(0) may return NULL; a Draco stream is never empty, but stay safe.
    unsigned char *bytes = static_cast<unsigned char *>(std::malloc(size ? size : 1));
    if (!bytes)
        return iso_error_set(err, ISO_E_NOMEM, "draco: no memory for %zu output bytes", size);
    std::memcpy(bytes, data, size);
    *out = bytes;
    *out_size = size;
    return 0;
}

int copy_out(const draco::EncoderBuffer &buf, unsigned char **out, size_t *out_size,
             iso_error *err)
{
    return copy_bytes(buf.data(), buf.size(), out, out_size, err);
}

int add_float3(draco::Mesh &dm, draco::GeometryAttribute::Type type, size_t count)
{
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, 3, draco::DT_FLOAT32, false, 3 * sizeof(float), 0);
    return dm.AddAttribute(ga, true, static_cast<uint32_t>(count));
}

// Draco's mesh encoders refuse a mesh without triangles (edgebreaker: "All triangles are
// degenerate"), 1.5.5 crashes quantizing an attribute with no values, and its sequential
// decoder rejects points without faces. What does work is the sequential encoding of a
// mesh with an unquantized POSITION attribute and no points: 22 bytes that every Draco
// decoder turns into an empty mesh. That is what an empty mesh encodes to.
int encode_empty(unsigned char **out, size_t *out_size, proto_draco_info *info, iso_error *err)
{
    draco::Mesh dm;
    int pos = add_float3(dm, draco::GeometryAttribute::POSITION, 0);
    if (pos < 0)
        return iso_error_set(err, ISO_E_NOMEM, "draco encode: cannot add POSITION");
    draco::Encoder enc;
    enc.SetSpeedOptions(10, 10);
    draco::EncoderBuffer buf;
    draco::Status st = enc.EncodeMeshToBuffer(dm, &buf);
    if (!st.ok())
        return iso_error_set(err, ISO_E_UNSUPPORTED, "draco encode (empty mesh): %s",
                             st.error_msg());
    if (info) {
        std::memset(info, 0, sizeof *info);
        info->position_id = static_cast<int>(dm.attribute(pos)->unique_id());
        info->normal_id = -1;
        info->speed = 10;
    }
    return copy_out(buf, out, out_size, err);
}

// The bounds a decoder will see: Draco quantizes on the grid ComputeParameters derives from
// the attribute (origin = min, one range = the largest extent) with these same Quantizer and
// Dequantizer classes, so running them here reproduces the decoded values bit for bit.
// Each step (float subtraction, round to the grid, scale, float addition) is monotone, so
// the decoded bounds are the raw bounds quantized: six values, not every point's three.
bool decoded_bounds(const draco::PointAttribute &att, int bits, float min[3], float max[3])
{
    draco::AttributeQuantizationTransform aq;
    if (!aq.ComputeParameters(att, bits))
        return false;
    const int32_t max_q = static_cast<int32_t>((1u << bits) - 1);
    draco::Quantizer q;
    draco::Dequantizer dq;
    q.Init(aq.range(), max_q);
    if (!dq.Init(aq.range(), max_q))
        return false;
    const float *v = reinterpret_cast<const float *>(att.buffer()->data());
    float lo[3] = {v[0], v[1], v[2]}, hi[3] = {v[0], v[1], v[2]};
    for (size_t i = 1; i < att.size(); i++)
        for (int c = 0; c < 3; c++) {
            lo[c] = std::min(lo[c], v[3 * i + c]);
            hi[c] = std::max(hi[c], v[3 * i + c]);
        }
    for (int c = 0; c < 3; c++) {
        float m = aq.min_value(c);
        min[c] = dq.DequantizeFloat(q.QuantizeFloat(lo[c] - m)) + m;
        max[c] = dq.DequantizeFloat(q.QuantizeFloat(hi[c] - m)) + m;
    }
    return true;
}

// A triangle with a repeated index: edgebreaker drops it, and it covers no area.
bool degenerate(const uint32_t *f)
{
    return f[0] == f[1] || f[1] == f[2] || f[2] == f[0];
}

// Encodes dm at `speed` into buf with a fresh enc. Quantization is explicit:
// without SetAttributeQuantization Draco stores raw floats. `compress` asks the sequential
// coder (speed 10) to delta- and entropy-code the indices instead of writing each as a
// varint: 2.4x smaller for CThead skin, and faster, as fewer bytes are written.
int run_encoder(const draco::Mesh &dm, const proto_encode_options *opt, int speed, bool compress,
                draco::Encoder *enc, draco::EncoderBuffer *buf, iso_error *err)
{
    enc->SetTrackEncodedProperties(true);
    enc->SetSpeedOptions(speed, speed);
    if (compress)
        enc->options().SetGlobalBool("compress_connectivity", true);
    enc->SetAttributeQuantization(draco::GeometryAttribute::POSITION, opt->position_bits);
    if (dm.GetNamedAttributeId(draco::GeometryAttribute::NORMAL) >= 0)
        enc->SetAttributeQuantization(draco::GeometryAttribute::NORMAL, opt->normal_bits);
    draco::Status st = enc->EncodeMeshToBuffer(dm, buf);
    if (!st.ok())
        return iso_error_set(err, ISO_E_UNSUPPORTED, "draco encode: %s", st.error_msg());
    return 0;
}

size_t varint_bytes(size_t v)
{
    size_t n = 1;
    for (; v >= 0x80; v >>= 7)
        n++;
    return n;
}

// Draco 1.5's sequential decoder refuses a stream that holds fewer than 3 bytes per face
// after its face and point counts (mesh_sequential_decoder.cc: a sanity check made for raw
// indices), which compressed indices undercut on smooth meshes: a 201k-triangle torus
// with normals takes 2.8. The header before the counts is 11 bytes ("DRACO", version,
// encoder type and method, flags); 16 more are kept as a margin.
bool sequential_decodable(size_t size, size_t faces, size_t points)
{
    size_t head = 11 + varint_bytes(faces) + varint_bytes(points) + 16;
    return size >= head && faces <= (size - head) / 3;
}

// Bits of an index delta as the sequential coder writes it: |d| << 1 | sign.
int delta_bits(int64_t d)
{
    uint64_t v = static_cast<uint64_t>(d < 0 ? -d : d) << 1;
    return v ? 64 - __builtin_clzll(v) : 0;
}

// The Draco faces and the vertex numbering (remap: mesh vertex -> Draco point, `unused`
// for vertices no proper triangle uses). Draco gets only used vertices, so its
// quantization grid, the decoded bounds and the point count do not depend on whether
// edgebreaker (which drops unused vertices) or the sequential coder (which keeps them)
// runs.
struct numbering {
    std::vector<uint32_t> remap;
    uint32_t used = 0;
    size_t faces = 0;
};

// Keeps the mesh's vertex order and each triangle's first corner: speed 10 by name
// promises the order (docs/api.md).
void number_in_order(const iso_mesh *mesh, draco::Mesh &dm, numbering &n)
{
    const uint32_t unused = UINT32_MAX;
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        if (degenerate(f))
            continue;
        for (int k = 0; k < 3; k++)
            n.remap[f[k]] = 0;
    }
    for (size_t v = 0; v < mesh->vertex_count; v++)
        if (n.remap[v] != unused)
            n.remap[v] = n.used++;
    draco::FaceIndex fi(0);
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        if (degenerate(f))
            continue;
        draco::Mesh::Face face;
        for (int k = 0; k < 3; k++)
            face[k] = draco::PointIndex(n.remap[f[k]]);
        dm.SetFace(fi, face);
        ++fi;
    }
    n.faces = fi.value();
}

// Numbers vertices in the order triangles first use them, and starts each triangle at the
// corner (of its three rotations, same winding) whose index deltas take the fewest bits.
// The sequential coder entropy-codes the delta of each index from the one before it;
// extraction numbers vertices as it makes them (brick by brick, a transition cell's centre
// after the crossings around it, a chain level in meshoptimizer's order), so in the mesh's
// own order those deltas can span far more ids than its neighbourhood, and small deltas
// also make a smaller alphabet, which shortens Draco's sort of symbol frequencies.
// Edgebreaker (speeds 0-9) renumbers anyway.
void number_by_first_use(const iso_mesh *mesh, draco::Mesh &dm, numbering &n)
{
    const uint32_t unused = UINT32_MAX;
    uint32_t *remap = n.remap.data();
    int64_t last = 0;
    draco::FaceIndex fi(0);
    for (size_t t = 0; t < mesh->triangle_count; t++) {
        const uint32_t *f = mesh->indices + 3 * t;
        if (degenerate(f))
            continue;
        // Rotation r writes the jump from `last` to corner r, then two of the three gaps
        // around the triangle: all but the one ending at corner r. Their common total
        // drops out of the comparison. New corners count as n.used (close enough to rank
        // the rotations; a tie keeps the mesh's own first corner).
        const uint32_t p0 = remap[f[0]], p1 = remap[f[1]], p2 = remap[f[2]];
        const int64_t i0 = p0 != unused ? p0 : n.used, i1 = p1 != unused ? p1 : n.used,
                      i2 = p2 != unused ? p2 : n.used;
        const int g01 = delta_bits(i1 - i0), g12 = delta_bits(i2 - i1), g20 = delta_bits(i0 - i2);
        const int b0 = delta_bits(i0 - last) - g20, b1 = delta_bits(i1 - last) - g01,
                  b2 = delta_bits(i2 - last) - g12;
        const int r = b0 <= b1 && b0 <= b2 ? 0 : b1 <= b2 ? 1 : 2;
        const uint32_t v[3] = {f[r], f[r == 2 ? 0 : r + 1], f[r == 0 ? 2 : r - 1]};
        draco::Mesh::Face face;
        for (int k = 0; k < 3; k++) {
            if (remap[v[k]] == unused)
                remap[v[k]] = n.used++;
            face[k] = draco::PointIndex(remap[v[k]]);
        }
        last = face[2].value();
        dm.SetFace(fi, face);
        ++fi;
    }
    n.faces = fi.value();
}

// Writes the used vertices' positions (and normals) into dm's new attributes; their ids
// in *pos and *nrm (-1: no normals).
int add_attributes(const iso_mesh *mesh, const numbering &num, draco::Mesh &dm, int *pos,
                   int *nrm, iso_error *err)
{
    const uint32_t unused = UINT32_MAX;
    dm.set_num_points(num.used);
    *pos = add_float3(dm, draco::GeometryAttribute::POSITION, num.used);
    *nrm = mesh->normals ? add_float3(dm, draco::GeometryAttribute::NORMAL, num.used) : -1;
    if (*pos < 0 || (mesh->normals && *nrm < 0))
        return iso_error_set(err, ISO_E_NOMEM, "draco encode: cannot add attributes");
    float *p = reinterpret_cast<float *>(dm.attribute(*pos)->buffer()->data());
    float *n = *nrm >= 0 ? reinterpret_cast<float *>(dm.attribute(*nrm)->buffer()->data()) : nullptr;
    for (size_t v = 0; v < mesh->vertex_count; v++) {
        const uint32_t at = num.remap[v];
        if (at == unused)
            continue;
        std::memcpy(p + 3 * static_cast<size_t>(at), mesh->positions + 3 * v, 3 * sizeof(float));
        if (n)
            std::memcpy(n + 3 * static_cast<size_t>(at), mesh->normals + 3 * v, 3 * sizeof(float));
    }
    return 0;
}

// One half of a split encode: its own encoder, buffer and error, as it runs on its own
// thread.
struct half {
    const draco::Mesh *dm;
    const proto_encode_options *opt;
    draco::Encoder enc;
    draco::EncoderBuffer buf;
    iso_error err = {};
    int rc = 0;
};

void encode_half(void *context, int t, int threads)
{
    (void)threads;
    half *h = static_cast<half *>(context) + t;
    try {
        h->rc = run_encoder(*h->dm, h->opt, 10, true, &h->enc, &h->buf, &h->err);
    } catch (...) {
        h->rc = exception_status(&h->err, "encode", ISO_E_UNSUPPORTED);
    }
}

// A Draco header: "DRACO", version (2 bytes), encoder type, method, flags (2 bytes).
const size_t draco_header_bytes = 11;

// The sequential coder writes connectivity and attributes one after the other, each from
// its own data: the indices from the faces, the attributes in point order (linear
// sequencer, delta prediction at speed 10) whatever the faces. So the two run on two
// threads as two streams, `conn` (the faces, no attributes: it ends with a zero count of
// attribute encoders) and `attrs` (the attributes, no faces: its connectivity is the
// counts 0 and `points`, then the method byte), and the stream is conn's head and
// connectivity followed by attrs' attributes: the bytes one encoder writes
// (test_draco_split_matches_one_encoder). Returns false, with *out untouched, if the
// halves do not have that layout.
bool splice(const draco::EncoderBuffer &conn, const draco::EncoderBuffer &attrs,
            uint32_t points, std::vector<char> *out)
{
    draco::EncoderBuffer counts;
    draco::EncodeVarint(static_cast<uint32_t>(0), &counts);
    draco::EncodeVarint(points, &counts);
    counts.Encode(static_cast<uint8_t>(0)); // compressed indices, none
    const size_t head = draco_header_bytes, skip = head + counts.size();
    if (conn.size() <= head || attrs.size() < skip || conn.data()[conn.size() - 1] != 0 ||
        std::memcmp(conn.data(), attrs.data(), head) != 0 ||
        std::memcmp(attrs.data() + head, counts.data(), counts.size()) != 0)
        return false;
    out->reserve(conn.size() - 1 + attrs.size() - skip);
    out->assign(conn.data(), conn.data() + conn.size() - 1);
    out->insert(out->end(), attrs.data() + skip, attrs.data() + attrs.size());
    return true;
}

int encode(const iso_mesh *mesh, const proto_encode_options *opt, unsigned char **out,
           size_t *out_size, proto_draco_info *info, iso_error *err)
{
    // PASS 1 (reads indices, writes remap and the Draco faces).
    const size_t nt = mesh->triangle_count;
    draco::Mesh dm;
    numbering num;
    num.remap.assign(mesh->vertex_count, UINT32_MAX);
    dm.SetNumFaces(nt);
    if (opt->speed == 10)
        number_in_order(mesh, dm, num);
    else
        number_by_first_use(mesh, dm, num);
    const size_t faces = num.faces;
    if (faces == 0)
        return encode_empty(out, out_size, info, err);
    dm.SetNumFaces(faces);
    int speed = opt->speed == PROTO_DRACO_SPEED_AUTO ? proto_draco_auto_speed(faces) : opt->speed;
    const bool split = speed == 10 && iso_parallel_threads(opt->threads) > 1;

    // PASS 2 (reads the mesh, writes the Draco attributes): used vertices, into a mesh of
    // their own when connectivity and attributes are encoded apart.
    draco::Mesh points;
    draco::Mesh &attrs = split ? points : dm;
    int pos, nrm, rc = add_attributes(mesh, num, attrs, &pos, &nrm, err);
    if (rc)
        return rc;
    if (split)
        dm.set_num_points(num.used);

    draco::Encoder first, second, *enc = &first;
    draco::EncoderBuffer buf;
    std::vector<char> spliced;
    bool done = false;
    if (split) {
        half halves[2];
        halves[0].dm = &dm, halves[1].dm = &points;
        halves[0].opt = halves[1].opt = opt;
        iso_parallel_run(2, encode_half, halves);
        for (const half &h : halves)
            if (h.rc) {
                *err = h.err;
                return h.rc;
            }
        done = splice(halves[0].buf, halves[1].buf, num.used, &spliced);
    }
    // One mesh for one encoder, if one has to run: the faces join the attributes.
    draco::Mesh &whole = split ? points : dm;
    bool joined = !split;
    auto join = [&]() {
        if (joined)
            return;
        points.SetNumFaces(faces);
        for (draco::FaceIndex f(0); f < faces; ++f)
            points.SetFace(f, dm.face(f));
        joined = true;
    };
    if (!done) {
        join();
        rc = run_encoder(whole, opt, speed, speed == 10, enc, &buf, err);
        if (rc)
            return rc;
    }
    size_t size = done ? spliced.size() : buf.size();
    if (speed == 10 && !sequential_decodable(size, faces, num.used)) {
        // Auto promises no order, so it takes edgebreaker's compact stream; speed 10 asked
        // by name keeps its order with raw indices.
        speed = opt->speed == PROTO_DRACO_SPEED_AUTO ? 8 : 10;
        enc = &second;
        buf.Clear();
        done = false;
        join();
        rc = run_encoder(whole, opt, speed, false, enc, &buf, err);
        if (rc)
            return rc;
    }

    if (info) {
        std::memset(info, 0, sizeof *info);
        info->points = done ? num.used : enc->num_encoded_points();
        info->faces = done ? faces : enc->num_encoded_faces();
        info->position_id = static_cast<int>(whole.attribute(pos)->unique_id());
        info->normal_id = nrm >= 0 ? static_cast<int>(whole.attribute(nrm)->unique_id()) : -1;
        info->speed = speed;
        if (!decoded_bounds(*whole.attribute(pos), opt->position_bits, info->min, info->max))
            return iso_error_set(err, ISO_E_UNSUPPORTED, "draco encode: no quantization grid");
    }
    if (done)
        return copy_bytes(spliced.data(), spliced.size(), out, out_size, err);
    return copy_out(buf, out, out_size, err);
}

// Reads a decoded 3-component float attribute into floats, point by point. The bytes are
// copied, not converted: ConvertValue reads the attribute's `normalized` flag, a bool that
// libdraco fills from the stream unchecked, so a hostile stream made it load a bool of
// value 2 (undefined behaviour; found by tests/fuzz/fuzz_draco, input kept in
// tests/fuzz/regressions/draco/). Float attributes, which dequantized positions and
// normals always are, never need the flag.
bool read_float3(const draco::PointAttribute &att, size_t points, float *dst)
{
    if (att.data_type() != draco::DT_FLOAT32 || att.num_components() != 3 || !att.buffer())
        return false;
    const size_t stride = static_cast<size_t>(att.byte_stride()), offset = static_cast<size_t>(att.byte_offset());
    const size_t bytes = static_cast<size_t>(att.buffer()->data_size());
    for (size_t i = 0; i < points; i++) {
        draco::AttributeValueIndex avi = att.mapped_index(draco::PointIndex(static_cast<uint32_t>(i)));
        size_t at = offset + stride * static_cast<size_t>(avi.value());
        if (avi.value() >= att.size() || stride < 3 * sizeof(float) || at > bytes || bytes - at < 3 * sizeof(float))
            return false;
        std::memcpy(dst + 3 * i, att.buffer()->data() + at, 3 * sizeof(float));
    }
    return true;
}

int decode(const void *data, size_t size, iso_mesh *m, iso_error *err)
{
    draco::DecoderBuffer db;
    db.Init(static_cast<const char *>(data), size);
    draco::Decoder dec;
    auto res = dec.DecodeMeshFromBuffer(&db);
    if (!res.ok())
        return iso_error_set(err, ISO_E_FORMAT, "draco decode: %s", res.status().error_msg());
    const draco::Mesh &dm = *res.value();
    const draco::PointAttribute *pa = dm.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    if (!pa || pa->num_components() != 3)
        return iso_error_set(err, ISO_E_FORMAT, "draco decode: no 3-component POSITION");
    const draco::PointAttribute *na = dm.GetNamedAttribute(draco::GeometryAttribute::NORMAL);
    if (na && na->num_components() != 3)
        na = nullptr; // not ours: dropped rather than refused, positions are what matter
    const size_t np = dm.num_points(), nf = dm.num_faces();

    int rc = iso_mesh_reserve(m, np, nf);
    if (rc)
        return iso_error_set(err, rc, "draco decode: no memory for %zu points, %zu faces", np, nf);
    if (na && np) {
        // iso_mesh_reserve grows normals only once they exist; size them like positions.
        m->normals = static_cast<float *>(std::malloc(m->vertex_capacity * 3 * sizeof(float)));
        if (!m->normals)
            return iso_error_set(err, ISO_E_NOMEM, "draco decode: no memory for normals");
    }
    if (!read_float3(*pa, np, m->positions) || (m->normals && !read_float3(*na, np, m->normals)))
        return iso_error_set(err, ISO_E_FORMAT, "draco decode: attribute value out of range");
    for (size_t t = 0; t < nf; t++) {
        const draco::Mesh::Face &f = dm.face(draco::FaceIndex(static_cast<uint32_t>(t)));
        for (int k = 0; k < 3; k++) {
            if (f[k].value() >= np)
                return iso_error_set(err, ISO_E_FORMAT, "draco decode: face %zu index %u >= %zu",
                                     t, f[k].value(), np);
            m->indices[3 * t + k] = f[k].value();
        }
    }
    m->vertex_count = np;
    m->triangle_count = nf;
    return 0;
}

} // namespace

extern "C" int proto_draco_auto_speed(size_t triangles)
{
    return triangles <= PROTO_DRACO_AUTO_SEQUENTIAL ? 8 : 10;
}

extern "C" int proto_draco_encode_info(const iso_mesh *mesh, const proto_encode_options *opt,
                                       unsigned char **out, size_t *out_size,
                                       proto_draco_info *info, iso_error *err)
{
    assert(mesh && out && out_size);
    *out = nullptr;
    *out_size = 0;
    proto_encode_options defaults;
    if (!opt) {
        proto_encode_options_init(&defaults);
        opt = &defaults;
    }
    if (opt->position_bits < PROTO_POSITION_BITS_MIN || opt->position_bits > PROTO_POSITION_BITS_MAX)
        return iso_error_set(err, ISO_E_ARGUMENT, "position bits %d outside %d..%d",
                             opt->position_bits, PROTO_POSITION_BITS_MIN, PROTO_POSITION_BITS_MAX);
    if (opt->normal_bits < PROTO_NORMAL_BITS_MIN || opt->normal_bits > PROTO_NORMAL_BITS_MAX)
        return iso_error_set(err, ISO_E_ARGUMENT, "normal bits %d outside %d..%d",
                             opt->normal_bits, PROTO_NORMAL_BITS_MIN, PROTO_NORMAL_BITS_MAX);
    if (opt->speed != PROTO_DRACO_SPEED_AUTO &&
        (opt->speed < PROTO_DRACO_SPEED_MIN || opt->speed > PROTO_DRACO_SPEED_MAX))
        return iso_error_set(err, ISO_E_ARGUMENT, "draco speed %d outside %d..%d (or auto)",
                             opt->speed, PROTO_DRACO_SPEED_MIN, PROTO_DRACO_SPEED_MAX);
    int rc = proto_mesh_check(mesh, 1, err);
    if (rc)
        return rc;
    try {
        return encode(mesh, opt, out, out_size, info, err);
    } catch (...) {
        return exception_status(err, "encode", ISO_E_UNSUPPORTED);
    }
}

extern "C" int proto_encode_draco(const iso_mesh *mesh, const proto_encode_options *opt,
                                  unsigned char **out, size_t *out_size, iso_error *err)
{
    return proto_draco_encode_info(mesh, opt, out, out_size, nullptr, err);
}

extern "C" int proto_draco_decode(const void *data, size_t size, iso_mesh *out, iso_error *err)
{
    assert(out && (data || size == 0));
    iso_mesh_init(out);
    if (size == 0)
        return iso_error_set(err, ISO_E_FORMAT, "draco decode: no data");
    int rc;
    try {
        rc = decode(data, size, out, err);
    } catch (...) {
        rc = exception_status(err, "decode", ISO_E_FORMAT);
    }
    if (rc)
        iso_mesh_free(out);
    return rc;
}
