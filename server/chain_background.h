/* chain_background.h: the background builder of chains (chains.h). Once preloading is
 * done, the chains of every preloaded volume's suggested levels (those /v1/volumes lists;
 * tolerance 0, no cap: what the viewer's Detail asks for first) are built one at a time on
 * one thread at the lowest priority (SCHED_IDLE, else nice 19), never on the pool's
 * threads, and written beside the hierarchy files, so that a restart maps them instead.
 * A chain already in its file is only mapped; one a request is building is left to it.
 * Then, and with --chain-background off too, the same thread completes the partial chains
 * requests built only down to their level (chains.h), one at a time, each written and
 * mapped in place of the one in memory. Progress goes to the registry (srv_chain_progress: /v1/status) and to the terminal. */
#ifndef SRV_CHAIN_BACKGROUND_H
#define SRV_CHAIN_BACKGROUND_H

#include <pthread.h>
#include <stdatomic.h>

#include "chains.h"
#include "collection.h"

typedef struct srv_chain_background {
    srv_collection *collection;
    srv_chains *chains;
    pthread_t thread;
    int started, suggested;
    _Atomic int stop, finished;
} srv_chain_background;

/* Starts the thread, which waits for preloading to end, builds the suggested levels'
 * chains when `suggested` (--chain-background on), then completes the partial chains
 * requests made (srv_chains_defer) until stopped. 0 or ISO_E_NOMEM (no thread: requests
 * then extend partial chains as far as they need, and none is written). */
int srv_chain_background_start(srv_chain_background *b, srv_collection *collection, srv_chains *chains,
                               int suggested);
/* Asks it to stop after the chain at hand (the completions left queued are dropped, their
 * chains left partial) and waits up to timeout_ms: 0 stopped (or never
 * started), 1 still building (a chain cannot be cut short: the caller must then leave the
 * collection and the registry allocated, as the thread still uses them). */
int srv_chain_background_stop(srv_chain_background *b, double timeout_ms);

#endif
