/* sha256.h: a small SHA-256 (FIPS 180-4) for tests that check data against published hashes. */
#ifndef ISO_SHA256_H
#define ISO_SHA256_H

#include <stddef.h>
#include <stdint.h>

typedef struct sha256_ctx {
    uint32_t state[8];
    uint64_t length;       /* bytes hashed so far */
    unsigned char block[64];
    size_t used;           /* bytes waiting in block */
} sha256_ctx;

void sha256_init(sha256_ctx *ctx);
void sha256_update(sha256_ctx *ctx, const void *data, size_t size);
/* Writes the 32-byte digest; ctx must be initialised again before reuse. */
void sha256_final(sha256_ctx *ctx, unsigned char digest[32]);
/* Digest as 64 lowercase hex digits plus a NUL. */
void sha256_hex(const unsigned char digest[32], char hex[65]);

#endif
