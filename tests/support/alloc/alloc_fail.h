/* alloc_fail.h: a process-wide allocator that fails one chosen allocation, for the
 * allocation-failure sweeps (test_oom, test_http_oom).
 *
 * malloc, calloc and realloc are defined over glibc's own (__libc_malloc ...), which every
 * library of the process calls, libstdc++'s operator new (and so libdraco) included. Armed,
 * it counts allocations on every thread and makes the one numbered fail_at (0-based) return
 * NULL; it also counts live blocks, so a run can check that it left none behind. Only the
 * two sweep binaries link it (the Makefile keeps it out of the other tests). The sanitizer
 * build's allocator is ASan's, which replaces the same symbols: there ALLOC_FAIL_AVAILABLE
 * is 0 and the sweeps say SKIP. */
#ifndef ALLOC_FAIL_H
#define ALLOC_FAIL_H

#if defined(__SANITIZE_ADDRESS__)
#define ALLOC_FAIL_AVAILABLE 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ALLOC_FAIL_AVAILABLE 0
#endif
#endif
#ifndef ALLOC_FAIL_AVAILABLE
#define ALLOC_FAIL_AVAILABLE 1
#endif

/* Starts counting from zero; allocation number fail_at fails (-1: none does). */
void alloc_fail_arm(long fail_at);
/* Stops counting; returns the allocations asked for since alloc_fail_arm. */
long alloc_fail_disarm(void);
/* Blocks allocated minus blocks freed since alloc_fail_arm. */
long alloc_fail_live(void);

#endif
