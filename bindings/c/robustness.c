/* Garbage through every function of Waymark's C ABI (issue 7): NULL pointers, invalid UTF-8,
 * NaN, infinities, huge values, out-of-order and extreme timestamps, truncated and malformed
 * site JSON, a callback that calls back into the engine. Every call must return a result code
 * (never crash, never leak: test.sh runs this under valgrind), and the engine must position
 * normally afterwards. Calls after waymark_engine_free cannot be detected in C (the handle is
 * a dangling pointer) and are not tried. Usage: robustness site.json */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "waymark.h"
#include "check.h"

/* One of the result codes the header defines. */
static int known(waymark_result r) {
    return r == WAYMARK_RESULT_OK || r == WAYMARK_RESULT_NULL_PARAMETER || r == WAYMARK_RESULT_INVALID_SITE ||
           r == WAYMARK_RESULT_INVALID_CONFIG || r == WAYMARK_RESULT_INPUT_REJECTED ||
           r == WAYMARK_RESULT_NO_POSITION || r == WAYMARK_RESULT_INVALID_UTF8 || r == WAYMARK_RESULT_SALT_MISMATCH ||
           r == WAYMARK_RESULT_HABITS_REJECTED || r == WAYMARK_RESULT_BUFFER_TOO_SMALL || r == WAYMARK_RESULT_PANIC;
}

static int finite_position(const waymark_position *p) {
    return isfinite(p->x) && isfinite(p->y) && isfinite(p->floor_probability) && isfinite(p->accuracy_m) &&
           isfinite(p->accuracy_95_m) && p->accuracy_m > 0 && p->accuracy_95_m >= p->accuracy_m &&
           isfinite(p->beyond_radio_m) && p->beyond_radio_m >= 0 && p->accuracy_m >= p->beyond_radio_m &&
           (isnan(p->heading_deg) || isfinite(p->heading_deg)) && p->motion_state <= 2 && p->scenario <= 3;
}

static const char *const BAD_UTF8[] = {"\xff", "02:00:00:00:00:0\xc3", "\xed\xa0\x80", "\xc0\xaf"};
static const char *const BAD_TEXT[] = {"", " ", "not a mac", "zz:zz:zz:zz:zz:zz", "02:00:00:00:00",
                                       "02:00:00:00:00:00:00", "\xf0\x9f\x92\xa5"};
#define COUNT(a) (sizeof(a) / sizeof *(a))

static void sites(const char *site_path, const char *json, size_t len) {
    waymark_engine *engine = NULL;
    /* NULLs. */
    CHECK(waymark_engine_new(NULL, 10, &engine) == WAYMARK_RESULT_NULL_PARAMETER, "null json");
    CHECK(waymark_engine_new((const uint8_t *)json, len, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null out");
    CHECK(waymark_engine_new_from_path(NULL, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null path, out");
    CHECK(waymark_engine_new_from_path(site_path, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null out");
    /* Empty, truncated at many places, not UTF-8, embedded NUL, deeply nested. */
    CHECK(waymark_engine_new((const uint8_t *)json, 0, &engine) == WAYMARK_RESULT_INVALID_SITE, "empty json");
    for (size_t k = 1; k < 24; k++) {
        size_t cut = len * k / 24;
        CHECK(waymark_engine_new((const uint8_t *)json, cut, &engine) == WAYMARK_RESULT_INVALID_SITE,
              "json cut at %zu of %zu", cut, len);
    }
    const uint8_t not_utf8[] = {'{', '"', 0xff, 0xfe, '"', ':', '1', '}'};
    CHECK(waymark_engine_new(not_utf8, sizeof not_utf8, &engine) == WAYMARK_RESULT_INVALID_SITE, "bytes");
    char *copy = malloc(len);
    if (copy) {
        memcpy(copy, json, len);
        copy[len / 2] = 0;
        CHECK(waymark_engine_new((const uint8_t *)copy, len, &engine) == WAYMARK_RESULT_INVALID_SITE, "NUL");
        free(copy);
    }
    size_t deep = 1000000;
    char *nested = malloc(deep);
    if (nested) {
        memset(nested, '[', deep);
        CHECK(waymark_engine_new((const uint8_t *)nested, deep, &engine) == WAYMARK_RESULT_INVALID_SITE, "[[[");
        free(nested);
    }
    /* Paths: not UTF-8, empty, a directory, a device, too long. */
    for (size_t i = 0; i < COUNT(BAD_UTF8); i++) {
        CHECK(waymark_engine_new_from_path(BAD_UTF8[i], &engine) == WAYMARK_RESULT_INVALID_UTF8, "path %zu", i);
    }
    const char *paths[] = {"", "/", "/dev/null", "/proc/self"};
    for (size_t i = 0; i < COUNT(paths); i++) {
        CHECK(waymark_engine_new_from_path(paths[i], &engine) == WAYMARK_RESULT_INVALID_SITE, "path %s", paths[i]);
    }
    char *long_path = malloc(100001);
    if (long_path) {
        memset(long_path, 'x', 100000);
        long_path[100000] = 0;
        CHECK(waymark_engine_new_from_path(long_path, &engine) == WAYMARK_RESULT_INVALID_SITE, "long path");
        free(long_path);
    }
    CHECK(engine == NULL, "no engine came out of a failure");
    /* The last error: any buffer size, including none. */
    char one[1] = {'x'}, small[4];
    size_t n = waymark_last_error(NULL, 0);
    CHECK(n > 0, "a message");
    CHECK(waymark_last_error(one, 0) == n && one[0] == 'x', "len 0 writes nothing");
    CHECK(waymark_last_error(one, 1) == n && one[0] == 0, "len 1 writes the NUL");
    CHECK(waymark_last_error(small, sizeof small) == n && strlen(small) == 3, "truncated");
    waymark_engine_free(NULL);
}

/* printf to buf + *at, never past cap; *at counts what would have been written. */
static void append(char *buf, size_t cap, size_t *at, const char *format, ...) {
    va_list args;
    va_start(args, format);
    int n = vsnprintf(buf + (*at < cap ? *at : cap), *at < cap ? cap - *at : 0, format, args);
    va_end(args);
    *at += n > 0 ? (size_t)n : 0;
}

/* The site budget and the site readers (issue 60, items 1, 7 and 10; docs/errors.md#site-limits):
 * 20 000 states packed on a line 8/20 000 m apart, each within reach of every other, are refused
 * with INVALID_SITE naming the limit, where they asked for 2.4 GB and aborted; data after the
 * JSON document is refused, a UTF-8 byte order mark skipped; /dev/zero is refused after the
 * first block it reads. */
static void site_limits(const char *json, size_t len) {
    waymark_engine *engine = NULL;
    enum { STATES = 20000 };
    /* About 130 bytes a state and its edge; append() stops at the end and the CHECK below
     * fails if anything was cut. */
    size_t cap = (size_t)STATES * 200 + 1000, at = 0;
    char *dense = malloc(cap);
    if (!dense) {
        CHECK(0, "memory for the dense site");
        return;
    }
    append(dense, cap, &at,
           "{\"format_version\": 7, \"name\": \"dense\", \"floors\": [{\"name\": \"G\"}], \"radio\": "
           "{\"clip_dbm\": -100, \"unheard\": {\"mean_dbm\": -110, \"std_db\": 5}, "
           "\"transmitters\": [{\"wifi\": {\"bssid\": \"02:00:00:00:00:01\"}}]}, \"states\": [");
    for (int i = 0; i < STATES; i++) {
        append(dense, cap, &at,
               "%s{\"id\": %d, \"floor\": 0, \"x\": %.9f, \"y\": 0, "
               "\"fingerprint\": [{\"tx\": 0, \"mean_dbm\": -60, \"std_db\": 4}]}",
               i ? "," : "", i, i * 8.0 / STATES);
    }
    append(dense, cap, &at, "], \"edges\": [");
    for (int i = 1; i < STATES; i++) {
        append(dense, cap, &at, "%s{\"from\": %d, \"to\": %d}", i > 1 ? "," : "", i - 1, i);
    }
    append(dense, cap, &at, "]}");
    CHECK(at < cap, "the dense site fits its buffer");
    CHECK(waymark_engine_new((const uint8_t *)dense, at, &engine) == WAYMARK_RESULT_INVALID_SITE, "dense site");
    char message[512];
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "MAX_REACHABLE_STATES") != NULL, "the limit is named: %s", message);
    free(dense);
    /* The site file followed by more data, and after a byte order mark. */
    char *longer = malloc(len + 8);
    if (longer) {
        memcpy(longer, json, len);
        memcpy(longer + len, "\n{}", 3);
        CHECK(waymark_engine_new((const uint8_t *)longer, len + 3, &engine) == WAYMARK_RESULT_INVALID_SITE,
              "trailing data");
        waymark_last_error(message, sizeof message);
        CHECK(strstr(message, "after the end") != NULL, "trailing data is named: %s", message);
        memcpy(longer, "\xef\xbb\xbf", 3);
        memcpy(longer + 3, json, len);
        CHECK(waymark_engine_new((const uint8_t *)longer, len + 3, &engine) == WAYMARK_RESULT_OK, "a UTF-8 BOM");
        waymark_engine_free(engine);
        engine = NULL;
        free(longer);
    }
    CHECK(waymark_engine_new_from_path("/dev/zero", &engine) == WAYMARK_RESULT_INVALID_SITE, "/dev/zero");
    CHECK(engine == NULL, "no engine came out of a failure");
}

/* Every engine function with a NULL engine. */
static void null_engine(void) {
    waymark_sample s = {1, 0, 0, 9.8};
    waymark_position p;
    size_t accepted;
    CHECK(waymark_engine_push_accelerometer(NULL, &s, 1, &accepted) == WAYMARK_RESULT_NULL_PARAMETER, "acc");
    CHECK(waymark_engine_push_gyroscope(NULL, &s, 1, &accepted) == WAYMARK_RESULT_NULL_PARAMETER, "gyro");
    CHECK(waymark_engine_push_magnetometer(NULL, &s, 1, &accepted) == WAYMARK_RESULT_NULL_PARAMETER, "mag");
    waymark_wifi_reading w = {"02:00:00:00:00:00", -60.0, 0};
    CHECK(waymark_engine_push_scan(NULL, 1, &w, 1, NULL, 0, &p) == WAYMARK_RESULT_NULL_PARAMETER, "scan");
    CHECK(waymark_engine_advance(NULL, 1, &p) == WAYMARK_RESULT_NULL_PARAMETER, "advance");
    CHECK(waymark_engine_position(NULL, &p) == WAYMARK_RESULT_NULL_PARAMETER, "position");
    CHECK(waymark_engine_position(NULL, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "position, NULL out");
    CHECK(waymark_engine_set_callback(NULL, NULL, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "callback");
    CHECK(waymark_engine_push_fix(NULL, 1, 0, 0, -1, 3, &p) == WAYMARK_RESULT_NULL_PARAMETER, "fix");
    CHECK(waymark_engine_confirm_zone(NULL, 1, "aisle", &p) == WAYMARK_RESULT_NULL_PARAMETER, "confirm zone");
    CHECK(waymark_engine_confirm_position(NULL, 1, 0, 0, 0, 1, &p) == WAYMARK_RESULT_NULL_PARAMETER, "confirm position");
    size_t zones;
    double posterior[2];
    char name[8];
    CHECK(waymark_engine_zone_count(NULL, &zones) == WAYMARK_RESULT_NULL_PARAMETER, "zone count");
    CHECK(waymark_engine_zone_name(NULL, 0, name, sizeof name, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "zone name");
    CHECK(waymark_engine_zone_posterior(NULL, posterior, 2) == WAYMARK_RESULT_NULL_PARAMETER, "zone posterior");
    waymark_habit_report report;
    waymark_fix_bias fix_bias;
    size_t json_len;
    CHECK(waymark_engine_learn_habits(NULL, &report) == WAYMARK_RESULT_NULL_PARAMETER, "learn habits");
    CHECK(waymark_engine_learn_habits(NULL, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "learn habits, NULL out");
    CHECK(waymark_engine_export_habits(NULL, name, sizeof name, &json_len) == WAYMARK_RESULT_NULL_PARAMETER,
          "export habits");
    CHECK(waymark_engine_import_habits(NULL, "{}") == WAYMARK_RESULT_NULL_PARAMETER, "import habits");
    CHECK(waymark_engine_clear_habits(NULL) == WAYMARK_RESULT_NULL_PARAMETER, "clear habits");
    CHECK(waymark_engine_fix_bias(NULL, &fix_bias) == WAYMARK_RESULT_NULL_PARAMETER, "fix error");
}

/* A callback that calls back into the engine: no lock is held while it runs. */
static int reentrant_calls = 0;
static void reentrant(void *userdata, const waymark_position *p) {
    waymark_engine *engine = userdata;
    waymark_position again;
    reentrant_calls++;
    CHECK(p != NULL && finite_position(p), "callback position");
    CHECK(waymark_engine_position(engine, &again) == WAYMARK_RESULT_OK, "position from the callback");
    waymark_sample s = {p->timestamp_ns + 1, 0, 0, 9.81};
    CHECK(waymark_engine_push_accelerometer(engine, &s, 1, NULL) == WAYMARK_RESULT_OK, "push from the callback");
    CHECK(waymark_engine_learn_habits(engine, NULL) == WAYMARK_RESULT_OK, "learn from the callback");
}

static void garbage(waymark_engine *engine) {
    waymark_position p;
    size_t accepted = 99;
    typedef waymark_result (*push_fn)(waymark_engine *, const waymark_sample *, size_t, size_t *);
    push_fn pushes[] = {waymark_engine_push_accelerometer, waymark_engine_push_gyroscope,
                        waymark_engine_push_magnetometer};
    const double weird[] = {NAN, INFINITY, -INFINITY, 1e300, -1e300, 1e7, -0.0, 5e-324};
    for (size_t k = 0; k < COUNT(pushes); k++) {
        CHECK(pushes[k](engine, NULL, 0, &accepted) == WAYMARK_RESULT_OK && accepted == 0, "empty batch");
        CHECK(pushes[k](engine, NULL, 5, &accepted) == WAYMARK_RESULT_NULL_PARAMETER, "NULL batch");
        waymark_sample bad[3 * COUNT(weird)];
        for (size_t i = 0; i < COUNT(weird); i++) {
            bad[3 * i] = (waymark_sample){100 + i, weird[i], 0, 9.8};
            bad[3 * i + 1] = (waymark_sample){100 + i, 0, weird[i], 9.8};
            bad[3 * i + 2] = (waymark_sample){100 + i, 0, 0, weird[i]};
        }
        CHECK(pushes[k](engine, bad, COUNT(bad), &accepted) == WAYMARK_RESULT_OK && accepted <= 2,
              "weird values: %zu taken", accepted);
        waymark_sample times[] = {{50, 0, 0, 9.8}, {40, 0, 0, 9.8}, {50, 0, 0, 9.8}, {0, 0, 0, 9.8},
                                  {UINT64_MAX - 1, 0, 0, 9.8}, {60, 0, 0, 9.8}};
        CHECK(pushes[k](engine, times, COUNT(times), NULL) == WAYMARK_RESULT_OK, "backwards samples");
    }

    const char *known = "02:00:00:00:00:00";
    uint64_t t = 1000;
    /* Readings: NULL arrays with counts, NULL and non-UTF-8 strings, bad ids, weird RSSI and ages. */
    CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, NULL, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED, "empty");
    CHECK(waymark_engine_push_scan(engine, ++t, NULL, 3, NULL, 0, &p) == WAYMARK_RESULT_NULL_PARAMETER, "wifi");
    CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, NULL, 3, &p) == WAYMARK_RESULT_NULL_PARAMETER, "ble");
    waymark_wifi_reading null_bssid = {NULL, -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, ++t, &null_bssid, 1, NULL, 0, &p) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL bssid");
    for (size_t i = 0; i < COUNT(BAD_UTF8); i++) {
        waymark_wifi_reading w = {BAD_UTF8[i], -60.0, 0};
        CHECK(waymark_engine_push_scan(engine, ++t, &w, 1, NULL, 0, &p) == WAYMARK_RESULT_INVALID_UTF8, "bssid %zu", i);
        waymark_beacon_reading u = {BAD_UTF8[i], 1, 2, -60.0, 0, NULL};
        CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, &u, 1, &p) == WAYMARK_RESULT_INVALID_UTF8, "uuid %zu", i);
        waymark_beacon_reading a = {NULL, 0, 0, -60.0, 0, BAD_UTF8[i]};
        CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, &a, 1, &p) == WAYMARK_RESULT_INVALID_UTF8, "mac %zu", i);
    }
    for (size_t i = 0; i < COUNT(BAD_TEXT); i++) {
        waymark_wifi_reading w = {BAD_TEXT[i], -60.0, 0};
        CHECK(waymark_engine_push_scan(engine, ++t, &w, 1, NULL, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED, "bssid");
        waymark_beacon_reading u = {BAD_TEXT[i], 1, 2, -60.0, 0, NULL};
        CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, &u, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED, "uuid");
        waymark_beacon_reading a = {NULL, 0, 0, -60.0, 0, BAD_TEXT[i]};
        CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, &a, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED, "mac");
    }
    waymark_beacon_reading nothing = {NULL, 0, 0, -60.0, 0, NULL};
    CHECK(waymark_engine_push_scan(engine, ++t, NULL, 0, &nothing, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED, "none");
    const double rssi[] = {NAN, INFINITY, -INFINITY, 1e300, -1e300, 1001.0};
    for (size_t i = 0; i < COUNT(rssi); i++) {
        waymark_wifi_reading w[2] = {{known, -60.0, 0}, {known, rssi[i], 0}};
        CHECK(waymark_engine_push_scan(engine, ++t, w, 2, NULL, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED, "rssi %zu", i);
    }
    /* Accepted: a huge age (with no age limit), duplicates, -0 dBm; each position finite. */
    waymark_wifi_reading odd[] = {{known, -60.0, UINT64_MAX}, {known, -61.0, 0}, {known, -0.0, 5}};
    for (size_t n = 1; n <= COUNT(odd); n++) {
        waymark_result r = waymark_engine_push_scan(engine, ++t, odd, n, NULL, 0, &p);
        CHECK(r == WAYMARK_RESULT_OK && finite_position(&p), "odd scan %zu: %d", n, (int)r);
    }
    size_t many = 20000;
    waymark_wifi_reading *lots = malloc(many * sizeof *lots);
    if (lots) {
        for (size_t i = 0; i < many; i++) lots[i] = (waymark_wifi_reading){known, -40.0 - (double)(i % 50), i};
        CHECK(waymark_engine_push_scan(engine, ++t, lots, many, NULL, 0, NULL) == WAYMARK_RESULT_OK, "20000 readings");
        free(lots);
    }
    /* Time: the same, earlier, zero; NULL out is allowed. */
    waymark_wifi_reading one = {known, -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, t, &one, 1, NULL, 0, NULL) == WAYMARK_RESULT_INPUT_REJECTED, "same time");
    CHECK(waymark_engine_push_scan(engine, 0, &one, 1, NULL, 0, NULL) == WAYMARK_RESULT_INPUT_REJECTED, "time 0");
    CHECK(waymark_engine_advance(engine, t, NULL) == WAYMARK_RESULT_INPUT_REJECTED, "advance to the same time");
    CHECK(waymark_engine_advance(engine, ++t, NULL) == WAYMARK_RESULT_OK, "advance, NULL out");
    CHECK(waymark_engine_position(engine, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "position, NULL out");

    /* A callback that re-enters; then cleared; setting it twice replaces it. */
    CHECK(waymark_engine_set_callback(engine, reentrant, engine) == WAYMARK_RESULT_OK, "set");
    CHECK(waymark_engine_set_callback(engine, reentrant, engine) == WAYMARK_RESULT_OK, "set again");
    t += 1000000000ull;
    CHECK(waymark_engine_push_scan(engine, t, &one, 1, NULL, 0, &p) == WAYMARK_RESULT_OK, "scan with callback");
    t += 1000000000ull;
    CHECK(waymark_engine_advance(engine, t, &p) == WAYMARK_RESULT_OK, "advance with callback");
    CHECK(reentrant_calls == 2, "%d callbacks", reentrant_calls);
    CHECK(waymark_engine_set_callback(engine, NULL, engine) == WAYMARK_RESULT_OK, "clear");
    t += 1000000000ull;
    CHECK(waymark_engine_advance(engine, t, &p) == WAYMARK_RESULT_OK && reentrant_calls == 2, "cleared");
}

/* The C ABI's edges (issue 60): options no person or compass has, a zone name cut inside a
 * character, reading counts whose sum overflows. */
static void abi_edges(const char *json, size_t len) {
    waymark_engine *engine = NULL;
    waymark_engine_options options;
    const double steps[] = {1e300, 70.0, 0.01};
    for (size_t i = 0; i < COUNT(steps); i++) {
        waymark_engine_options_default(&options);
        options.step_length_m = steps[i];
        CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
                      WAYMARK_RESULT_INVALID_CONFIG && engine == NULL,
              "step length %g m", steps[i]);
    }
    waymark_engine_options_default(&options);
    options.declination_deg = 1e300;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
                  WAYMARK_RESULT_INVALID_CONFIG && engine == NULL,
          "declination 1e300");
    waymark_engine_options_default(&options);
    options.site_rotation_deg = -1e300;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
                  WAYMARK_RESULT_INVALID_CONFIG && engine == NULL,
          "site rotation -1e300");
    waymark_engine_options_default(&options);
    options.step_length_m = 0.75;
    options.declination_deg = -12.5;
    options.site_rotation_deg = 270;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) == WAYMARK_RESULT_OK,
          "plausible options");
    if (engine) {
        /* Counts whose sum overflows, or whose arrays no memory holds: refused before any
         * reading is touched (the pointers are not NULL but point to one reading each). */
        waymark_wifi_reading w = {"02:00:00:00:00:00", -60.0, 0};
        waymark_beacon_reading b = {NULL, 0, 0, -60.0, 0, "02:00:00:00:00:01"};
        CHECK(waymark_engine_push_scan(engine, 10, &w, SIZE_MAX, &b, 1, NULL) == WAYMARK_RESULT_INPUT_REJECTED,
              "wifi_count + beacon_count overflows");
        CHECK(waymark_engine_push_scan(engine, 10, &w, SIZE_MAX / 2, &b, SIZE_MAX / 2, NULL) ==
                  WAYMARK_RESULT_INPUT_REJECTED,
              "counts no memory holds");
        CHECK(waymark_engine_push_scan(engine, 10, &w, 1, &b, 1, NULL) == WAYMARK_RESULT_OK, "then a real scan");
        waymark_engine_free(engine);
        engine = NULL;
    }

    /* A zone name of multi-byte characters: "caf\u00e9 \u2615" is 9 bytes (c a f, 2 for the
     * e-acute, a space, 3 for the cup). */
    const char *from = "\"name\":\"aisle\"", *to = "\"name\":\"caf\xc3\xa9 \xe2\x98\x95\"";
    const char *at = strstr(json, from);
    CHECK(at != NULL, "the site has a zone named aisle");
    if (!at) return;
    size_t head = (size_t)(at - json), tail = len - head - strlen(from);
    size_t utf8_len = head + strlen(to) + tail;
    char *utf8 = malloc(utf8_len);
    if (!utf8) return;
    memcpy(utf8, json, head);
    memcpy(utf8 + head, to, strlen(to));
    memcpy(utf8 + head + strlen(to), at + strlen(from), tail);
    CHECK(waymark_engine_new((const uint8_t *)utf8, utf8_len, &engine) == WAYMARK_RESULT_OK, "site with UTF-8");
    free(utf8);
    if (!engine) return;
    size_t zone = SIZE_MAX, zones = 0, name_len = 0;
    waymark_engine_zone_count(engine, &zones);
    char name[16];
    for (size_t z = 0; z < zones; z++) {
        waymark_engine_zone_name(engine, z, name, sizeof name, NULL);
        if (strcmp(name, "caf\xc3\xa9 \xe2\x98\x95") == 0) zone = z;
    }
    CHECK(zone != SIZE_MAX, "the UTF-8 zone is there");
    /* Room for 4 bytes and the NUL cuts inside the e-acute, for 8 inside the cup: only whole
     * characters are written. */
    char five[5], nine[9];
    CHECK(waymark_engine_zone_name(engine, zone, five, sizeof five, &name_len) == WAYMARK_RESULT_OK &&
              strcmp(five, "caf") == 0 && name_len == 9,
          "cut before the e-acute: \"%s\" (%zu)", five, name_len);
    CHECK(waymark_engine_zone_name(engine, zone, nine, sizeof nine, &name_len) == WAYMARK_RESULT_OK &&
              strcmp(nine, "caf\xc3\xa9 ") == 0 && name_len == 9,
          "cut before the cup: \"%s\" (%zu)", nine, name_len);
    waymark_engine_free(engine);
}

/* Habits after the garbage: learning from that history works, and garbage models are refused
 * with a code while the engine's model stays as it was. */
static void habit_garbage(waymark_engine *engine) {
    waymark_habit_report r;
    CHECK(waymark_engine_learn_habits(engine, &r) == WAYMARK_RESULT_OK, "learn from the garbage's history");
    waymark_fix_bias e;
    CHECK(waymark_engine_fix_bias(engine, &e) == WAYMARK_RESULT_OK && isfinite(e.bias_x_m) &&
              isfinite(e.bias_y_m) && e.spread > 0,
          "finite fix error");
    (void)r;
    size_t len = 0, got = 0;
    CHECK(waymark_engine_export_habits(engine, NULL, 0, &len) == WAYMARK_RESULT_BUFFER_TOO_SMALL, "length");
    char *json = malloc(len + 1), *after = malloc(len + 1);
    CHECK(waymark_engine_export_habits(engine, json, len + 1, NULL) == WAYMARK_RESULT_OK, "export");
    char tiny[1] = {'x'};
    CHECK(waymark_engine_export_habits(engine, tiny, 1, &got) == WAYMARK_RESULT_BUFFER_TOO_SMALL && tiny[0] == 0 &&
              got == len,
          "one-byte buffer");
    CHECK(waymark_engine_export_habits(engine, NULL, 1, &got) == WAYMARK_RESULT_NULL_PARAMETER, "NULL buffer");
    for (size_t i = 0; i < COUNT(BAD_UTF8); i++)
        CHECK(waymark_engine_import_habits(engine, BAD_UTF8[i]) == WAYMARK_RESULT_INVALID_UTF8, "model %zu", i);
    for (size_t i = 0; i < COUNT(BAD_TEXT); i++)
        CHECK(waymark_engine_import_habits(engine, BAD_TEXT[i]) == WAYMARK_RESULT_HABITS_REJECTED, "model %zu", i);
    const char *models[] = {
        "{\"format\":\"waymark-habits\"}",
        "{\"format\":\"waymark-habits\",\"version\":-1}",
        "{\"format\":\"waymark-habits\",\"version\":1e999}",
        "{\"format\":\"waymark-habits\",\"version\":18446744073709551616}",
        "{\"format\":\"waymark-habits\",\"version\":1,\"epochs\":NaN}",
    };
    for (size_t i = 0; i < COUNT(models); i++)
        CHECK(waymark_engine_import_habits(engine, models[i]) == WAYMARK_RESULT_HABITS_REJECTED, "model %s",
              models[i]);
    size_t deep = 100000;
    char *nested = malloc(deep + 1);
    if (nested) {
        memset(nested, '[', deep);
        nested[deep] = 0;
        CHECK(waymark_engine_import_habits(engine, nested) == WAYMARK_RESULT_HABITS_REJECTED, "[[[");
        memset(nested, '{', deep);
        CHECK(waymark_engine_import_habits(engine, nested) == WAYMARK_RESULT_HABITS_REJECTED, "{{{");
        free(nested);
    }
    CHECK(waymark_engine_export_habits(engine, after, len + 1, &got) == WAYMARK_RESULT_OK && strcmp(after, json) == 0,
          "refused models changed the habits");
    CHECK(waymark_engine_import_habits(engine, json) == WAYMARK_RESULT_OK, "its own model back");
    free(json);
    free(after);
}

int main(int argc, char **argv) {
    size_t len = 0;
    char *json = site_argument(argc, argv, &len);
    sites(argv[1], json, len);
    site_limits(json, len);
    null_engine();
    abi_edges(json, len);

    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &engine) == WAYMARK_RESULT_OK, "site");
    free(json);
    if (!engine) return 1;
    garbage(engine);
    habit_garbage(engine);

    /* After all that, the engine positions as usual and every result code was a known one. */
    waymark_position before, p;
    CHECK(waymark_engine_position(engine, &before) == WAYMARK_RESULT_OK && finite_position(&before), "position");
    waymark_wifi_reading scan[] = {{"02:00:00:00:00:00", -55.0, 0}, {"02:00:00:00:00:01", -70.0, 0},
                                   {"02:00:00:00:00:02", -80.0, 0}};
    for (int k = 1; k <= 5; k++) {
        waymark_result r = waymark_engine_push_scan(engine, before.timestamp_ns + (uint64_t)k * 1500000000ull, scan,
                                                    COUNT(scan), NULL, 0, &p);
        CHECK(known(r) && r == WAYMARK_RESULT_OK && finite_position(&p), "scan %d after the garbage: %d", k, (int)r);
    }
    /* Past any phone's clock (a negative int64 passed as unsigned): refused, not adopted. */
    CHECK(waymark_engine_advance(engine, UINT64_MAX, &p) == WAYMARK_RESULT_INPUT_REJECTED, "past the clock");
    CHECK(waymark_engine_advance(engine, INT64_MAX, &p) == WAYMARK_RESULT_OK && finite_position(&p), "end of time");
    CHECK(waymark_engine_advance(engine, INT64_MAX, &p) == WAYMARK_RESULT_INPUT_REJECTED, "past the end of time");
    waymark_engine_free(engine);
    printf("%d passed, %d failed\n", checks - failures, failures);
    return failures ? 1 : 0;
}
