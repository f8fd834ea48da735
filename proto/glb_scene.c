/* glb_scene.c: one glTF binary holding several named, coloured meshes (a segmentation's
 * segments), made by joining the single-mesh glbs of glb.c (Draco) or glb_meshopt.c
 * (meshopt), so that each mesh is encoded exactly as the one-mesh routes encode it.
 *
 * PASS 1 (split): each part's container read back: its JSON (jansson) and its BIN chunk.
 * PASS 2 (join): the parts' BIN chunks end to end (each 4-byte aligned already); every
 *   index a part's JSON holds (accessors, buffer views, meshes) moved past the parts
 *   before it, and every byte offset into the BIN chunk (a view's, a meshopt view's
 *   compressed one) moved past their bytes; meshopt's uncompressed fallback buffers become
 *   one, the offsets into it moved the same way. Per part a node named after its mesh, with
 *   the part's dequantizing transform, and a material whose baseColorFactor is the colour
 *   in linear light (glTF's convention); a part with no triangles gives a node with no mesh.
 * PASS 3 (write): the JSON, compact, and the joined BIN chunk in one container. */
#include "encode.h"
#include "glb_container.h"
#include "segment/segment.h"

#include <assert.h>
#include <jansson.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* PASS 1: the JSON and BIN chunks of a glb this module's encoders made. */
static int split(const unsigned char *glb, size_t size, json_t **json, const unsigned char **bin, size_t *bin_size,
                 iso_error *err)
{
    *json = NULL;
    *bin = NULL;
    *bin_size = 0;
    if (size < 20 || memcmp(glb, "glTF", 4))
        return iso_error_set(err, ISO_E_INTERNAL, "a part of the scene is not a glb");
    uint32_t json_length, bin_length;
    memcpy(&json_length, glb + 12, 4);
    if (json_length > size - 20)
        return iso_error_set(err, ISO_E_INTERNAL, "a part of the scene has a truncated JSON chunk");
    json_error_t je;
    *json = json_loadb((const char *)glb + 20, json_length, 0, &je);
    if (!*json)
        return iso_error_set(err, ISO_E_NOMEM, "reading a part of the scene: %s", je.text);
    size_t at = 20 + (size_t)json_length;
    if (at + 8 <= size) {
        memcpy(&bin_length, glb + at, 4);
        if (bin_length > size - at - 8) {
            json_decref(*json);
            *json = NULL;
            return iso_error_set(err, ISO_E_INTERNAL, "a part of the scene has a truncated BIN chunk");
        }
        *bin = glb + at + 8;
        *bin_size = bin_length;
    }
    return 0;
}

static json_int_t integer(json_t *object, const char *key)
{
    return json_integer_value(json_object_get(object, key));
}

static void shift(json_t *object, const char *key, json_int_t by)
{
    json_t *v = json_object_get(object, key);
    if (json_is_integer(v))
        json_integer_set(v, json_integer_value(v) + by);
}

/* Appends the array `from`'s items to `to` (both arrays; from may be NULL). */
static int extend(json_t *to, json_t *from)
{
    return json_is_array(from) ? json_array_extend(to, from) : 0;
}

typedef struct joined {
    json_t *root, *nodes, *meshes, *materials, *accessors, *views, *used;
    size_t bin_size, fallback_size;
    json_int_t accessor_base, view_base;
} joined;

/* PASS 2 for one part: its mesh (if any) joined, its node and material added. */
static int join_part(joined *j, json_t *part, size_t bin_base, const proto_scene_part *p, size_t index)
{
    json_t *nodes = json_object_get(part, "nodes"), *node = json_array_get(nodes, 0);
    json_t *new_node = json_object();
    json_t *extras = json_pack("{s:I}", "segment", (json_int_t)p->number);
    if (!new_node || !extras || json_object_set_new(new_node, "name", json_string(p->name)) ||
        json_object_set_new(new_node, "extras", extras))
        return ISO_E_NOMEM;
    if (node) {
        json_t *buffers = json_object_get(part, "buffers");
        size_t fallback_base = j->fallback_size;
        json_t *fallback = json_array_get(buffers, 1);
        if (fallback)
            j->fallback_size += (size_t)integer(fallback, "byteLength");
        json_t *accessors = json_object_get(part, "accessors"), *views = json_object_get(part, "bufferViews");
        size_t i;
        json_t *item;
        json_array_foreach(accessors, i, item) shift(item, "bufferView", j->view_base);
        json_array_foreach(views, i, item) {
            json_t *meshopt = json_object_get(json_object_get(item, "extensions"), "EXT_meshopt_compression");
            if (integer(item, "buffer") == 0)
                shift(item, "byteOffset", (json_int_t)bin_base);
            else
                shift(item, "byteOffset", (json_int_t)fallback_base);
            if (meshopt)
                shift(meshopt, "byteOffset", (json_int_t)bin_base);
        }
        json_t *mesh = json_array_get(json_object_get(part, "meshes"), 0);
        json_t *primitive = json_array_get(json_object_get(mesh, "primitives"), 0);
        json_t *attributes = json_object_get(primitive, "attributes");
        const char *key;
        json_object_foreach(attributes, key, item) json_integer_set(item, json_integer_value(item) + j->accessor_base);
        shift(primitive, "indices", j->accessor_base);
        json_t *draco = json_object_get(json_object_get(primitive, "extensions"), "KHR_draco_mesh_compression");
        if (draco)
            shift(draco, "bufferView", j->view_base);
        if (json_object_set_new(primitive, "material", json_integer((json_int_t)index)) ||
            json_object_set_new(mesh, "name", json_string(p->name)))
            return ISO_E_NOMEM;
        j->accessor_base += (json_int_t)json_array_size(accessors);
        j->view_base += (json_int_t)json_array_size(views);
        if (extend(j->accessors, accessors) || extend(j->views, views) || json_array_append(j->meshes, mesh))
            return ISO_E_NOMEM;
        json_t *transform;
        if ((transform = json_object_get(node, "translation")))
            json_object_set(new_node, "translation", transform);
        if ((transform = json_object_get(node, "scale")))
            json_object_set(new_node, "scale", transform);
        json_object_set_new(new_node, "mesh", json_integer((json_int_t)json_array_size(j->meshes) - 1));
        json_t *used = json_object_get(part, "extensionsUsed");
        if (!json_array_size(j->used))
            extend(j->used, used);
    }
    json_t *material = json_pack("{s:s, s:{s:[f,f,f,f], s:f, s:f}}", "name", p->name, "pbrMetallicRoughness",
                                 "baseColorFactor", (double)iso_seg_srgb_to_linear(p->color[0]), (double)iso_seg_srgb_to_linear(p->color[1]),
                                 (double)iso_seg_srgb_to_linear(p->color[2]), 1.0, "metallicFactor", 0.0, "roughnessFactor", 0.6);
    if (!material || json_array_append_new(j->materials, material) || json_array_append_new(j->nodes, new_node))
        return ISO_E_NOMEM;
    return 0;
}

int proto_glb_scene(const proto_scene_part *parts, size_t count, unsigned char **out, size_t *out_size,
                    iso_error *err)
{
    assert(out && out_size);
    *out = NULL;
    *out_size = 0;
    joined j = {0};
    j.root = json_object();
    j.nodes = json_array(), j.meshes = json_array(), j.materials = json_array();
    j.accessors = json_array(), j.views = json_array(), j.used = json_array();
    unsigned char *bin = NULL;
    int rc = 0;
    if (!j.root || !j.nodes || !j.meshes || !j.materials || !j.accessors || !j.views || !j.used)
        rc = ISO_E_NOMEM;
    /* The BIN chunk: the parts' end to end. */
    size_t total = 0;
    for (size_t i = 0; i < count; i++)
        total += parts[i].size;
    if (!rc && !(bin = malloc(total ? total : 1)))
        rc = ISO_E_NOMEM;
    for (size_t i = 0; i < count && !rc; i++) {
        json_t *part;
        const unsigned char *chunk;
        size_t chunk_size;
        if ((rc = split(parts[i].glb, parts[i].size, &part, &chunk, &chunk_size, err)))
            break;
        size_t base = j.bin_size;
        memcpy(bin + base, chunk, chunk_size);
        j.bin_size += proto_glb_pad4(chunk_size);
        rc = join_part(&j, part, base, &parts[i], i);
        json_decref(part);
    }
    if (rc == ISO_E_NOMEM)
        iso_error_set(err, rc, "out of memory joining %zu meshes into one glb", count);
    json_t *scene_nodes = json_array();
    for (size_t i = 0; !rc && i < count; i++)
        if (!scene_nodes || json_array_append_new(scene_nodes, json_integer((json_int_t)i)))
            rc = iso_error_set(err, ISO_E_NOMEM, "out of memory joining %zu meshes into one glb", count);
    if (!rc) {
        json_t *buffers = json_array();
        json_array_append_new(buffers, json_pack("{s:I}", "byteLength", (json_int_t)j.bin_size));
        if (j.fallback_size)
            json_array_append_new(buffers, json_pack("{s:I, s:{s:{s:b}}}", "byteLength", (json_int_t)j.fallback_size,
                                                     "extensions", "EXT_meshopt_compression", "fallback", 1));
        json_object_set_new(j.root, "asset", json_pack("{s:s, s:s}", "version", "2.0", "generator", "isoserve"));
        if (json_array_size(j.used)) {
            json_object_set(j.root, "extensionsUsed", j.used);
            json_object_set(j.root, "extensionsRequired", j.used);
        }
        json_object_set_new(j.root, "scene", json_integer(0));
        json_object_set_new(j.root, "scenes", json_pack("[{s:o}]", "nodes", scene_nodes));
        scene_nodes = NULL;
        json_object_set(j.root, "nodes", j.nodes);
        json_object_set(j.root, "materials", j.materials);
        if (json_array_size(j.meshes)) {
            json_object_set(j.root, "meshes", j.meshes);
            json_object_set(j.root, "accessors", j.accessors);
            json_object_set(j.root, "bufferViews", j.views);
            json_object_set_new(j.root, "buffers", buffers);
        } else {
            json_decref(buffers);
        }
        char *text = json_dumps(j.root, JSON_COMPACT | JSON_REAL_PRECISION(9));
        if (!text)
            rc = iso_error_set(err, ISO_E_NOMEM, "out of memory writing the scene's JSON");
        else
            rc = proto_glb_write_text(text, strlen(text), bin, json_array_size(j.meshes) ? j.bin_size : 0, out,
                                      out_size, err);
        free(text);
    }
    json_decref(scene_nodes);
    free(bin);
    json_decref(j.root);
    json_decref(j.nodes);
    json_decref(j.meshes);
    json_decref(j.materials);
    json_decref(j.accessors);
    json_decref(j.views);
    json_decref(j.used);
    return rc;
}
