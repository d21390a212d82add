/* The callback contract of the header (docs/errors.md#callbacks), as a hostile app tries it:
 * an engine freed from its own position callback, from its status callback on a rejected scan
 * and from the log callback; a log callback that calls the engine (and fails a call of its
 * own); a panic that must reach the log callback and not the host's stderr. test.sh runs it
 * under valgrind: a use-after-free is an invalid read there, a leak a failure. A deadlock ends
 * the run through the alarm below instead of hanging it. Usage: callbacks site.json */
#define _POSIX_C_SOURCE 200809L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "waymark.h"
#include "check.h"

/* Long enough for valgrind on a slow machine; a hang is the bug this file tests for. */
#define WATCHDOG_S 600

static const char *site_json;
static size_t site_len;

static waymark_engine *new_engine(void) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)site_json, site_len, &engine) == WAYMARK_RESULT_OK, "engine");
    return engine;
}

static const waymark_wifi_reading KNOWN = {"02:00:00:00:00:00", -60.0, 0};
static const waymark_wifi_reading UNKNOWN = {"0a:0b:0c:0d:0e:0f", -60.0, 0};

/* Frees the engine (userdata) at its first position, and counts how often it is called. */
static int position_calls = 0;
static void free_on_position(void *userdata, const waymark_position *p) {
    (void)p;
    position_calls++;
    waymark_engine_free(userdata);
}

/* Frees the engine (userdata) at the first failed call it reports. */
static int error_statuses = 0;
static void free_on_error(void *userdata, const waymark_status *s) {
    if (s->kind != WAYMARK_STATUS_KIND_ERROR) return;
    error_statuses++;
    waymark_engine_free(userdata);
}

static void free_from_own_callbacks(void) {
    /* The position callback frees the engine: the scan still returns its position, and the
     * engine is freed when the call returns (valgrind: no invalid read, no leak). */
    waymark_engine *engine = new_engine();
    if (!engine) return;
    CHECK(waymark_engine_set_callback(engine, free_on_position, engine) == WAYMARK_RESULT_OK, "set callback");
    waymark_position p;
    CHECK(waymark_engine_push_scan(engine, 1000000000ull, &KNOWN, 1, NULL, 0, &p) == WAYMARK_RESULT_OK &&
              p.timestamp_ns == 1000000000ull,
          "scan whose callback frees the engine");
    CHECK(position_calls == 1, "%d position callbacks", position_calls);

    /* The status callback frees it on a scan the engine rejects: the scan of no known
     * transmitter makes two statuses (no coverage, then the error); nothing after the free is
     * called. */
    engine = new_engine();
    if (!engine) return;
    CHECK(waymark_engine_set_status_callback(engine, free_on_error, engine) == WAYMARK_RESULT_OK, "set status");
    CHECK(waymark_engine_set_callback(engine, free_on_position, engine) == WAYMARK_RESULT_OK, "set callback");
    CHECK(waymark_engine_push_scan(engine, 1000000000ull, &UNKNOWN, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "rejected scan whose status callback frees the engine");
    CHECK(error_statuses == 1 && position_calls == 1, "%d errors, %d positions", error_statuses, position_calls);

    /* The same for input refused before it reaches the engine (a malformed BSSID). */
    engine = new_engine();
    if (!engine) return;
    CHECK(waymark_engine_set_status_callback(engine, free_on_error, engine) == WAYMARK_RESULT_OK, "set status");
    waymark_wifi_reading malformed = {"not a bssid", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, 1000000000ull, &malformed, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "malformed scan whose status callback frees the engine");
    CHECK(error_statuses == 2, "%d errors", error_statuses);
}

/* The log callback's engine, and what it does with it. */
static waymark_engine *logged_engine = NULL;
static enum { LOG_READS, LOG_FREES } log_action;
static int log_reads = 0, log_read_ok = 0, panic_records = 0;

static void on_log(void *userdata, uint32_t level, const char *target, const char *message) {
    (void)userdata;
    (void)target;
    if (level == WAYMARK_LOG_LEVEL_ERROR && strstr(message, "Waymark panicked") && strstr(message, "fault injected"))
        panic_records++;
    if (!logged_engine) return;
    if (log_action == LOG_FREES) {
        waymark_engine *engine = logged_engine;
        logged_engine = NULL;
        waymark_engine_free(engine);
        return;
    }
    /* Calls the engine on the thread that logged: this deadlocked when records were delivered
     * under the engine's lock. Then fails a call, which must not replace the logging call's
     * last error. */
    waymark_position p;
    waymark_result r = waymark_engine_position(logged_engine, &p);
    log_reads++;
    if (r == WAYMARK_RESULT_OK || r == WAYMARK_RESULT_NO_POSITION) log_read_ok++;
    char name[8];
    (void)waymark_engine_zone_name(logged_engine, 100000, name, sizeof name, NULL);
}

static void log_callback_calls_the_engine(void) {
    CHECK(waymark_set_log_callback(WAYMARK_LOG_LEVEL_DEBUG, on_log, NULL) == WAYMARK_RESULT_OK, "log callback");
    waymark_engine *engine = new_engine();
    if (!engine) return;
    logged_engine = engine;
    log_action = LOG_READS;
    /* A rejected scan logs "scan rejected" at DEBUG from inside the engine's lock. */
    CHECK(waymark_engine_push_scan(engine, 1000000000ull, &UNKNOWN, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "rejected scan with a log callback that calls the engine");
    CHECK(log_reads > 0 && log_read_ok == log_reads, "%d of %d reads from the log callback", log_read_ok, log_reads);
    char message[256];
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "zone") == NULL && strlen(message) > 0, "the scan's own last error: %s", message);
    CHECK(waymark_engine_push_scan(engine, 2000000000ull, &KNOWN, 1, NULL, 0, NULL) == WAYMARK_RESULT_OK,
          "the engine goes on");

    /* The log callback frees the engine. */
    log_action = LOG_FREES;
    CHECK(waymark_engine_push_scan(engine, 3000000000ull, &UNKNOWN, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "rejected scan with a log callback that frees the engine");
    CHECK(logged_engine == NULL, "the log callback freed the engine");
}

/* A panic inside Waymark (injected at UINT64_MAX - 7 in this test build) reaches the log
 * callback as an ERROR record and writes nothing to stderr. */
static void panic_stays_off_stderr(void) {
    waymark_engine *engine = new_engine();
    if (!engine) return;
    logged_engine = NULL;
    CHECK(waymark_set_log_callback(WAYMARK_LOG_LEVEL_WARN, on_log, NULL) == WAYMARK_RESULT_OK, "log callback");
    fflush(stderr);
    FILE *captured = tmpfile();
    int saved = dup(STDERR_FILENO);
    CHECK(captured && saved >= 0 && dup2(fileno(captured), STDERR_FILENO) >= 0, "capture stderr");
    waymark_result r = waymark_engine_push_scan(engine, UINT64_MAX - 7, &KNOWN, 1, NULL, 0, NULL);
    fflush(stderr);
    dup2(saved, STDERR_FILENO);
    close(saved);
    long written = -1;
    if (captured) {
        fseek(captured, 0, SEEK_END);
        written = ftell(captured);
        char head[200] = {0};
        rewind(captured);
        if (fread(head, 1, sizeof head - 1, captured) > 0) fprintf(stderr, "stderr during the panic: %s\n", head);
        fclose(captured);
    }
    CHECK(r == WAYMARK_RESULT_PANIC, "injected panic: %d", (int)r);
    CHECK(written == 0, "%ld bytes on stderr", written);
    CHECK(panic_records == 1, "%d panic records", panic_records);
    waymark_engine_free(engine);
    CHECK(waymark_set_log_callback(WAYMARK_LOG_LEVEL_ERROR, NULL, NULL) == WAYMARK_RESULT_OK, "no log callback");
}

int main(int argc, char **argv) {
    alarm(WATCHDOG_S);
    size_t len = 0;
    char *json = site_argument(argc, argv, &len);
    site_json = json;
    site_len = len;
    free_from_own_callbacks();
    log_callback_calls_the_engine();
    panic_stays_off_stderr();
    free(json);
    printf("%d passed, %d failed\n", checks - failures, failures);
    return failures ? 1 : 0;
}
