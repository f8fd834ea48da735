/* alloc_fail.c: the failing allocator of the allocation-failure sweeps (see alloc_fail.h). */
#include "alloc_fail.h"

#include <stdatomic.h>
#include <stddef.h>
#include <stdlib.h>

#if ALLOC_FAIL_AVAILABLE
void *__libc_malloc(size_t size);
void *__libc_calloc(size_t count, size_t size);
void *__libc_realloc(void *p, size_t size);
void __libc_free(void *p);

static atomic_int armed;    /* 1: count allocations and frees */
static atomic_long calls;   /* allocations asked for since armed */
static atomic_long fail_at; /* the one (0-based) that returns NULL; -1: none */
static atomic_long live;    /* blocks allocated minus blocks freed since armed */

/* 1 when this allocation must fail; counts it. */
static int fails(void)
{
    if (!atomic_load(&armed))
        return 0;
    return atomic_fetch_add(&calls, 1) == atomic_load(&fail_at);
}

static void *counted(void *p)
{
    if (p && atomic_load(&armed))
        atomic_fetch_add(&live, 1);
    return p;
}

void *malloc(size_t size)
{
    return fails() ? NULL : counted(__libc_malloc(size));
}

void *calloc(size_t count, size_t size)
{
    return fails() ? NULL : counted(__libc_calloc(count, size));
}

/* realloc(NULL, n) is an allocation; realloc(p, n) moves a block (no count change) or
 * fails leaving p alone; glibc's realloc(p, 0) frees p. */
void *realloc(void *p, size_t size)
{
    if (fails())
        return NULL;
    void *q = __libc_realloc(p, size);
    if (atomic_load(&armed)) {
        if (!p && q)
            atomic_fetch_add(&live, 1);
        else if (p && size == 0)
            atomic_fetch_sub(&live, 1);
    }
    return q;
}

void free(void *p)
{
    if (p && atomic_load(&armed))
        atomic_fetch_sub(&live, 1);
    __libc_free(p);
}

void alloc_fail_arm(long which)
{
    atomic_store(&calls, 0);
    atomic_store(&live, 0);
    atomic_store(&fail_at, which);
    atomic_store(&armed, 1);
}

long alloc_fail_disarm(void)
{
    atomic_store(&armed, 0);
    return atomic_load(&calls);
}

long alloc_fail_live(void)
{
    return atomic_load(&live);
}
#else
void alloc_fail_arm(long which)
{
    (void)which;
}

long alloc_fail_disarm(void)
{
    return 0;
}

long alloc_fail_live(void)
{
    return 0;
}
#endif
