/* fuzz_query.c: libFuzzer target for the mesh request parser (proto/query.c). The input is
 * a query string as a client sends it after decoding: '&' separates parameters, the first
 * '=' separates key and value (no '=': a bare key, value NULL), as libmicrohttpd hands
 * them over. Every parse must end in a request or a 400 problem, and a parsed request
 * must normalise to a key that parses back to the same key (the key spells "no budget"
 * and "no normals' bits" as budget=0 and qn=0, which a query leaves out instead). */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "query.h"

#define MAX_PARAMS 64

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size + 1);
    if (!text)
        return 0;
    memcpy(text, data, size);
    text[size] = '\0';
    proto_param params[MAX_PARAMS];
    size_t count = 0;
    for (char *save = NULL, *part = strtok_r(text, "&", &save); part && count < MAX_PARAMS;
         part = strtok_r(NULL, "&", &save)) {
        char *eq = strchr(part, '=');
        if (eq)
            *eq = '\0';
        params[count++] = (proto_param){part, eq ? eq + 1 : NULL};
    }
    proto_mesh_request req;
    proto_problem problem;
    if (proto_mesh_request_parse(params, count, &req, &problem) == 0) {
        char key[512], again[512];
        proto_mesh_request_key(&req, key, sizeof key);
        /* The key is itself a valid query with the same meaning. */
        char copy[512];
        memcpy(copy, key, sizeof copy);
        proto_param back[16];
        size_t n = 0;
        for (char *save = NULL, *part = strtok_r(copy, "&", &save); part && n < 16;
             part = strtok_r(NULL, "&", &save)) {
            char *eq = strchr(part, '=');
            *eq = '\0';
            if (strcmp(eq + 1, "0") || (strcmp(part, "budget") && strcmp(part, "qn")))
                back[n++] = (proto_param){part, eq + 1};
        }
        proto_mesh_request req2;
        if (proto_mesh_request_parse(back, n, &req2, &problem) != 0)
            abort();
        proto_mesh_request_key(&req2, again, sizeof again);
        if (strcmp(key, again) != 0)
            abort();
    } else if (problem.status != 400) {
        abort();
    }
    free(text);
    return 0;
}
