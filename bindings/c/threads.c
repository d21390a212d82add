/* Several threads pushing into one engine at once (issue 7). The position callback must be
 * called once per accepted epoch (none lost, none extra), in the order of the epochs, and never
 * from two threads at once; once waymark_engine_set_callback returns, the callback it replaced
 * is not running (so its userdata may be freed). A callback may replace itself. Run under
 * valgrind by test.sh. Usage: threads site.json */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "waymark.h"
#include "check.h"

#define PUSHERS 4
#define EPOCHS_PER_PUSHER 30
#define SWAPS 200
#define STEP_NS 20000000ull /* 20 ms between the times handed out */

/* Where a callback's userdata points. */
typedef struct {
    atomic_int inside; /* calls running now */
    atomic_int calls;
} sink;

static sink sinks[2];
static atomic_int running;  /* callbacks running now, whichever userdata */
static atomic_int overlaps; /* times a callback started while another was running */
static atomic_int handed;   /* positions passed to the callback by another thread than their pusher's */
static uint64_t delivered[PUSHERS * EPOCHS_PER_PUSHER + 8];
static atomic_int n_delivered;
static atomic_uint_fast64_t clock_ns = 1000000000ull;
static _Thread_local uint64_t pushing_ns; /* the epoch this thread is pushing, 0 if none */

static void on_position(void *userdata, const waymark_position *p) {
    sink *s = userdata;
    if (atomic_fetch_add(&running, 1) != 0) atomic_fetch_add(&overlaps, 1);
    atomic_fetch_add(&s->inside, 1);
    int k = atomic_fetch_add(&n_delivered, 1);
    if (k < (int)(sizeof delivered / sizeof *delivered)) delivered[k] = p->timestamp_ns;
    if (p->timestamp_ns != pushing_ns) atomic_fetch_add(&handed, 1);
    sched_yield(); /* give the other threads a chance to overlap, if they could */
    atomic_fetch_sub(&s->inside, 1);
    atomic_fetch_add(&s->calls, 1);
    atomic_fetch_sub(&running, 1);
}

typedef struct {
    waymark_engine *engine;
    uint64_t accepted[EPOCHS_PER_PUSHER];
    int n_accepted, rejected, wrong;
} pusher;

/* Scans and advances at times taken from one shared clock. Two threads can reach the engine in
 * the other order than they took their times: the later-taken time wins and the other is
 * rejected as out of order, so only accepted epochs are counted. */
static void *push(void *arg) {
    pusher *w = arg;
    waymark_wifi_reading scan[] = {{"02:00:00:00:00:00", -55.0, 0}, {"02:00:00:00:00:01", -70.0, 0},
                                   {"02:00:00:00:00:02", -80.0, 0}};
    for (int k = 0; k < EPOCHS_PER_PUSHER; k++) {
        uint64_t t = atomic_fetch_add(&clock_ns, STEP_NS) + STEP_NS;
        waymark_sample s = {t - 1000, 0.0, 0.0, 9.81};
        if (waymark_engine_push_accelerometer(w->engine, &s, 1, NULL) != WAYMARK_RESULT_OK) w->wrong++;
        waymark_position p;
        pushing_ns = t;
        waymark_result r = k % 3 == 2 ? waymark_engine_advance(w->engine, t, &p)
                                      : waymark_engine_push_scan(w->engine, t, scan, 3, NULL, 0, &p);
        pushing_ns = 0;
        if (r == WAYMARK_RESULT_OK && p.timestamp_ns == t) {
            w->accepted[w->n_accepted++] = t;
        } else if (r == WAYMARK_RESULT_INPUT_REJECTED) {
            w->rejected++;
        } else {
            w->wrong++;
        }
    }
    return NULL;
}

typedef struct {
    waymark_engine *engine;
    int errors, still_running;
} swapper;

/* Replaces the callback's userdata back and forth; the one replaced must not be running once
 * set_callback has returned. */
static void *swap(void *arg) {
    swapper *w = arg;
    for (int k = 0; k < SWAPS; k++) {
        sink *now = &sinks[(k + 1) % 2], *old = &sinks[k % 2];
        if (waymark_engine_set_callback(w->engine, on_position, now) != WAYMARK_RESULT_OK) w->errors++;
        if (atomic_load(&old->inside) != 0) w->still_running++;
        sched_yield();
    }
    return NULL;
}

static int compare(const void *a, const void *b) {
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return (x > y) - (x < y);
}

static void threads(waymark_engine *engine) {
    CHECK(waymark_engine_set_callback(engine, on_position, &sinks[0]) == WAYMARK_RESULT_OK, "callback");
    pusher pushers[PUSHERS];
    swapper swapping = {engine, 0, 0};
    pthread_t ids[PUSHERS + 1];
    memset(pushers, 0, sizeof pushers);
    for (int i = 0; i < PUSHERS; i++) {
        pushers[i].engine = engine;
        CHECK(pthread_create(&ids[i], NULL, push, &pushers[i]) == 0, "thread %d", i);
    }
    CHECK(pthread_create(&ids[PUSHERS], NULL, swap, &swapping) == 0, "swapper");
    for (int i = 0; i <= PUSHERS; i++) pthread_join(ids[i], NULL);

    /* Every call has returned, so every position has been delivered. */
    uint64_t accepted[PUSHERS * EPOCHS_PER_PUSHER];
    int n = 0, rejected = 0, wrong = 0;
    for (int i = 0; i < PUSHERS; i++) {
        memcpy(accepted + n, pushers[i].accepted, (size_t)pushers[i].n_accepted * sizeof *accepted);
        n += pushers[i].n_accepted;
        rejected += pushers[i].rejected;
        wrong += pushers[i].wrong;
    }
    qsort(accepted, (size_t)n, sizeof *accepted, compare);
    int got = atomic_load(&n_delivered);
    printf("threads: %d epochs accepted, %d rejected as out of order, %d callbacks (%d passed on by "
           "another thread), %d + %d per userdata\n",
           n, rejected, got, atomic_load(&handed), atomic_load(&sinks[0].calls), atomic_load(&sinks[1].calls));
    CHECK(wrong == 0, "%d calls failed", wrong);
    CHECK(n > EPOCHS_PER_PUSHER, "only %d epochs accepted", n);
    CHECK(n + rejected == PUSHERS * EPOCHS_PER_PUSHER, "every call accepted or rejected");
    CHECK(got == n, "%d callbacks for %d epochs", got, n);
    CHECK(atomic_load(&sinks[0].calls) + atomic_load(&sinks[1].calls) == n, "calls per userdata");
    CHECK(atomic_load(&overlaps) == 0, "%d callbacks ran at once", atomic_load(&overlaps));
    CHECK(swapping.errors == 0 && swapping.still_running == 0, "the replaced callback ran on %d times",
          swapping.still_running);
    int in_order = 1, same = 1;
    for (int k = 0; k < got && k < n; k++) {
        if (k > 0 && delivered[k] <= delivered[k - 1]) in_order = 0;
        if (delivered[k] != accepted[k]) same = 0;
    }
    CHECK(in_order, "callbacks out of the epochs' order");
    CHECK(same, "the callbacks' positions are not the accepted epochs'");
}

/* A callback that replaces itself: no deadlock, and the next position goes to the new one. */
static waymark_engine *self_replacing_engine;
static atomic_int replaced_calls;
static void replace_self(void *userdata, const waymark_position *p) {
    (void)p;
    atomic_fetch_add(&replaced_calls, 1);
    waymark_engine_set_callback(self_replacing_engine, on_position, userdata);
}

static void replacing(waymark_engine *engine) {
    self_replacing_engine = engine;
    int before = atomic_load(&sinks[1].calls);
    CHECK(waymark_engine_set_callback(engine, replace_self, &sinks[1]) == WAYMARK_RESULT_OK, "set");
    uint64_t t = atomic_load(&clock_ns);
    CHECK(waymark_engine_advance(engine, t + STEP_NS, NULL) == WAYMARK_RESULT_OK, "advance");
    CHECK(waymark_engine_advance(engine, t + 2 * STEP_NS, NULL) == WAYMARK_RESULT_OK, "advance");
    CHECK(atomic_load(&replaced_calls) == 1 && atomic_load(&sinks[1].calls) == before + 1,
          "replaced from inside: %d, then %d", atomic_load(&replaced_calls), atomic_load(&sinks[1].calls) - before);
    CHECK(waymark_engine_set_callback(engine, NULL, NULL) == WAYMARK_RESULT_OK, "clear");
}

int main(int argc, char **argv) {
    size_t len = 0;
    char *json = site_argument(argc, argv, &len);
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &engine) == WAYMARK_RESULT_OK, "site");
    free(json);
    if (!engine) return 1;
    threads(engine);
    replacing(engine);
    waymark_engine_free(engine);
    printf("%d passed, %d failed\n", checks - failures, failures);
    return failures ? 1 : 0;
}
