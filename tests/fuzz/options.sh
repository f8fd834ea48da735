# Sourced by tests/fuzz/run.sh and test_fuzz.sh: how every fuzz target runs.
# A hostile input may ask a library for gigabytes in one allocation: libdraco reserved
# 3.9 GB for a 150-byte stream (tests/fuzz/regressions/draco/huge-reserve), and filled
# over a gigabyte for another (touched-reserve). The shims must turn a failed allocation
# into an error, so ASan fails any single allocation past 512 MiB (returning NULL, which
# operator new turns into std::bad_alloc) instead of libFuzzer calling a large malloc a
# crash; what a target really holds is still capped by -rss_limit_mb. No fuzzed input
# here legitimately needs a block that large.
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1:max_allocation_size_mb=512
FUZZ_LIMITS=(-rss_limit_mb=2048 -malloc_limit_mb=65536)
