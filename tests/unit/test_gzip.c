/* test_gzip.c: proto/gzip.c's deflate coder (Huffman-only and matching pieces) read back by
 * zlib's inflate byte for byte: empty and 1-byte inputs, random bytes, long runs (matches of
 * 258), matches at the 32 KB window's edge and just past it, every size up to 300 of a
 * repetitive text, pieces joined on one and two threads, and sizes against zlib's level 1. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "check.h"
#include "encode.h"

static uint64_t rng_state = 0x2545F4914F6CDD1Dull;
static uint32_t rng(void) /* xorshift64*, fixed seed: failures reproduce */
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 0x2545F4914F6CDD1Dull) >> 32);
}

/* in gzipped in `count` pieces cut at `ends` (the last at size), all matching (huffman 0),
 * all Huffman-only (1) or alternating (2), on `threads`; checked by inflating; returns the
 * member's size (0 on failure). */
static size_t gzip_checked(const unsigned char *in, size_t size, const size_t *ends, int count, int huffman,
                           int threads)
{
    proto_gzip_piece pieces[PROTO_GZIP_PIECES_MAX];
    for (int i = 0; i < count; i++)
        pieces[i] = (proto_gzip_piece){.end = i == count - 1 ? size : ends[i],
                                       .huffman = huffman == 2 ? i % 2 : huffman};
    unsigned char *gz = NULL;
    size_t gz_size = 0;
    iso_error err;
    CHECK_OK(proto_gzip_pieces(in, size, pieces, count, threads, &gz, &gz_size, &err), &err);
    if (gz)
        check_gunzip(gz, gz_size, in, size);
    free(gz);
    return gz_size;
}

static size_t gzip_whole(const unsigned char *in, size_t size, int huffman)
{
    return gzip_checked(in, size, NULL, 1, huffman, 1);
}

/* Words drawn from a small vocabulary: repeats at every distance, as an index stream has. */
static void fill_text(unsigned char *in, size_t size)
{
    static const char *words[] = {"mesh ", "vertex ", "index ", "edge ", "fifo ", "triangle ", "normal ",
                                  "quantized ", "stream ", "\x01\x02\x03", "\xff\xfe", "gzip "};
    size_t at = 0;
    while (at < size) {
        const char *w = words[rng() % (sizeof words / sizeof *words)];
        for (; *w && at < size; w++)
            in[at++] = (unsigned char)*w;
    }
}

static void test_empty_and_one_byte(void)
{
    unsigned char b = 'x';
    for (int huffman = 0; huffman < 2; huffman++) {
        size_t empty = gzip_whole(&b, 0, huffman), one = gzip_whole(&b, 1, huffman);
        CHECK(empty >= 18 && empty < 40);
        CHECK(one > empty && one < 100);
        /* Empty pieces before, between and after. */
        size_t ends[4] = {0, 0, 1, 1};
        CHECK(gzip_checked(&b, 1, ends, 4, huffman, 1) > 0);
        CHECK(gzip_checked(&b, 0, ends, 3, huffman, 2) > 0);
    }
}

/* Random bytes: nothing to match, so the matching coder must cost no more than literals. */
static void test_random_bytes(void)
{
    size_t size = 300000;
    unsigned char *in = malloc(size);
    CHECK(in != NULL);
    if (!in)
        return;
    for (size_t i = 0; i < size; i++)
        in[i] = (unsigned char)rng();
    size_t matched = gzip_whole(in, size, 0), huffman = gzip_whole(in, size, 1);
    CHECKF(matched <= size + size / 50 && huffman <= size + size / 50, "%zu, %zu of %zu", matched, huffman, size);
    free(in);
}

/* One byte 1 MB long, then runs of every length from 1 to 600 of alternating bytes: matches
 * of the longest length (258) at distance 1, across every 64 KB block's edge. */
static void test_long_runs(void)
{
    size_t size = 1u << 20;
    unsigned char *in = malloc(size + 200000);
    CHECK(in != NULL);
    if (!in)
        return;
    memset(in, 'a', size);
    size_t gz = gzip_whole(in, size, 0);
    /* 4065 matches of 258 bytes, a few bits each, and a header per 64 KB block. */
    CHECKF(gz > 0 && gz < size / 100, "%zu bytes for %zu", gz, size);
    size_t at = 0;
    for (size_t run = 1; run <= 600; run++)
        for (size_t k = 0; k < run; k++)
            in[at++] = (unsigned char)(run % 2 ? 'b' : 'c');
    CHECK(gzip_whole(in, at, 0) < at / 20);
    CHECK(gzip_whole(in, at, 1) > 0);
    free(in);
}

/* A random pattern, zeros, and the pattern again at distance 32768 (deflate's farthest:
 * the repeat is coded as matches of 258 and less) or 32769 (out of reach: literals again). */
static void test_window_edge(void)
{
    enum { PATTERN = 600 };
    size_t sizes[2] = {0, 0};
    for (int past = 0; past < 2; past++) {
        size_t size = 32768 + past + PATTERN;
        unsigned char *in = calloc(size, 1);
        CHECK(in != NULL);
        if (!in)
            return;
        rng_state = 12345;
        for (size_t i = 0; i < PATTERN; i++)
            in[i] = in[32768 + past + i] = (unsigned char)(rng() | 1);
        sizes[past] = gzip_whole(in, size, 0);
        free(in);
    }
    /* The reachable repeat costs a few matches instead of 600 literals. */
    CHECKF(sizes[0] + 400 < sizes[1], "%zu at 32768, %zu at 32769", sizes[0], sizes[1]);
    CHECKF(sizes[0] < PATTERN + 300, "%zu", sizes[0]);
}

/* Blocks whose codes reach 15 bits (Fibonacci counts of 22 symbols, shuffled, in each
 * 64 KB block), so that every code-length code is sent; their edges fall at every bit
 * position over 40 blocks. */
static void test_deep_codes(void)
{
    size_t block = 65536, size = 40 * block;
    unsigned char *in = malloc(size);
    CHECK(in != NULL);
    if (!in)
        return;
    for (size_t b = 0; b < size; b += block) {
        size_t at = b;
        for (uint32_t x = 1, y = 1, sym = 0; sym < 22; sym++, y = x + y, x = y - x)
            for (uint32_t k = 0; k < x; k++)
                in[at++] = (unsigned char)(sym * 7);
        while (at < b + block)
            in[at++] = (unsigned char)(200 + rng() % 50);
        for (size_t i = block - 1; i > 0; i--) {
            size_t j = rng() % (i + 1);
            unsigned char t = in[b + i];
            in[b + i] = in[b + j], in[b + j] = t;
        }
    }
    for (int huffman = 0; huffman < 2; huffman++)
        CHECK(gzip_whole(in, size, huffman) < size);
    free(in);
}

/* Every size from 0 to 300 of a repetitive text (the last bytes too short for a match, a
 * match that ends at the buffer's end), both coders. */
static void test_every_small_size(void)
{
    unsigned char in[300];
    fill_text(in, sizeof in);
    for (size_t n = 0; n <= sizeof in; n++)
        for (int huffman = 0; huffman < 2; huffman++)
            CHECK(gzip_whole(in, n, huffman) > 0);
}

/* A text of 2.5 MB in one to four pieces, matching, Huffman-only or alternating, one and two
 * threads: the same bytes back; and the matching coder within 5% of zlib's level 1 (the
 * fastest of zlib, which it replaced for the meshopt index stream). */
static void test_pieces_joined(void)
{
    size_t size = 5u << 19;
    unsigned char *in = malloc(size);
    CHECK(in != NULL);
    if (!in)
        return;
    fill_text(in, size);
    for (size_t i = size / 2; i < size / 2 + 100000; i++) /* a stretch of random bytes */
        in[i] = (unsigned char)rng();
    const size_t ends[3] = {size / 5, size / 2 + 7, size - 65536};
    for (int count = 1; count <= PROTO_GZIP_PIECES_MAX; count++)
        for (int huffman = 0; huffman < 3; huffman++)
            for (int threads = 1; threads <= 2; threads++)
                CHECK(gzip_checked(in, size, ends, count, huffman, threads) > 0);
    size_t ours = gzip_whole(in, size, 0), zlib;
    free(check_deflate(in, size, -15, 1, &zlib));
    CHECKF(ours < zlib + zlib / 20, "%zu bytes against zlib's %zu", ours, zlib);
    free(in);
}

int main(void)
{
    CHECK_RUN(test_empty_and_one_byte);
    CHECK_RUN(test_random_bytes);
    CHECK_RUN(test_long_runs);
    CHECK_RUN(test_window_edge);
    CHECK_RUN(test_deep_codes);
    CHECK_RUN(test_every_small_size);
    CHECK_RUN(test_pieces_joined);
    return check_finish();
}
