/* The C test of Waymark: loads a simulated site, replays a walk's raw IMU batches and WiFi
 * scans through the C ABI, checks positions against the truth, and exercises the error paths
 * (NULL, bad JSON, out-of-order time, NaN samples). The walk is replayed again on the same site
 * with its transmitter ids hashed, with the salt; without it or with another one the engine
 * refuses to start. Habits are learned from the walk, exported, imported into another engine,
 * refused when they do not fit, and cleared. Run under valgrind by test.sh. */
#define _DEFAULT_SOURCE /* mkdtemp */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "waymark.h"
#include "check.h"

static int callbacks = 0;
static void on_position(void *userdata, const waymark_position *p) {
    int *count = userdata;
    (*count)++;
    (void)p;
}

static waymark_sample *read_samples(FILE *f, size_t n) {
    waymark_sample *s = calloc(n ? n : 1, sizeof *s);
    for (size_t i = 0; i < n; i++) {
        unsigned long long t;
        if (fscanf(f, "%llu %lf %lf %lf", &t, &s[i].x, &s[i].y, &s[i].z) != 4) exit(2);
        s[i].timestamp_ns = t;
    }
    return s;
}

/* The salt file's hex digits as bytes into `salt` (at most `cap`); the byte count, or 0. */
/* The `nw` readings of a scan line; the BSSIDs live in `*bssids` (free both). */
static waymark_wifi_reading *read_scan(FILE *f, size_t nw, char (**bssids)[32]) {
    waymark_wifi_reading *w = calloc(nw ? nw : 1, sizeof *w);
    *bssids = calloc(nw ? nw : 1, sizeof **bssids);
    for (size_t i = 0; i < nw; i++) {
        if (fscanf(f, "%31s %lf", (*bssids)[i], &w[i].rssi_dbm) != 2) exit(2);
        w[i].bssid = (*bssids)[i];
    }
    return w;
}

static size_t read_salt(const char *path, uint8_t *salt, size_t cap) {
    size_t len = 0, n = 0;
    char *text = read_file(path, &len);
    if (!text) return 0;
    for (size_t i = 0; i + 1 < len && n < cap; i += 2) {
        unsigned int byte;
        if (sscanf(text + i, "%2x", &byte) != 1) break;
        salt[n++] = (uint8_t)byte;
    }
    free(text);
    return n;
}

static void walk(const char *site_path, const char *walk_path, const uint8_t *salt, size_t salt_len) {
    waymark_engine *engine = NULL;
    callbacks = 0;
    CHECK(waymark_engine_new_from_path_with_salt(site_path, salt, salt_len, &engine) == WAYMARK_RESULT_OK,
          "load site %s", site_path);
    CHECK(waymark_engine_set_callback(engine, on_position, &callbacks) == WAYMARK_RESULT_OK, "callback");
    FILE *f = fopen(walk_path, "r");
    CHECK(f != NULL, "open walk");
    if (!f) return;
    unsigned long long t;
    double tx, ty, error_sum = 0;
    size_t na, ng, nm, nw;
    int epochs = 0, positions = 0;
    while (fscanf(f, " E %llu %lf %lf %zu %zu %zu %zu", &t, &tx, &ty, &na, &ng, &nm, &nw) == 7) {
        waymark_sample *a = read_samples(f, na), *g = read_samples(f, ng), *m = read_samples(f, nm);
        size_t accepted = 0;
        CHECK(waymark_engine_push_accelerometer(engine, a, na, &accepted) == WAYMARK_RESULT_OK, "accel");
        CHECK(waymark_engine_push_gyroscope(engine, g, ng, NULL) == WAYMARK_RESULT_OK, "gyro");
        CHECK(waymark_engine_push_magnetometer(engine, m, nm, NULL) == WAYMARK_RESULT_OK, "mag");
        free(a);
        free(g);
        free(m);
        char (*bssids)[32] = NULL;
        waymark_wifi_reading *w = read_scan(f, nw, &bssids);
        waymark_position p;
        waymark_result r = waymark_engine_push_scan(engine, t, w, nw, NULL, 0, &p);
        if (r == WAYMARK_RESULT_OK) {
            positions++;
            error_sum += hypot(p.x - tx, p.y - ty);
            CHECK(p.accuracy_m > 0 && isfinite(p.x) && isfinite(p.y), "finite position");
            CHECK(p.accuracy_95_m >= p.accuracy_m, "the 95 percent circle holds the 68 percent one");
            CHECK(p.beyond_radio_m >= 0 && p.accuracy_m >= p.beyond_radio_m, "the radius holds the walk beyond the radio");
        } else {
            CHECK(r == WAYMARK_RESULT_INPUT_REJECTED, "scan result %d", (int)r);
        }
        free(w);
        free(bssids);
        epochs++;
    }
    fclose(f);
    double mean = positions ? error_sum / positions : INFINITY;
    printf("walk (%s ids): %d epochs, %d positions, mean error %.2f m, %d callbacks\n", salt ? "hashed" : "raw",
           epochs, positions, mean, callbacks);
    CHECK(epochs > 10 && positions > epochs / 2, "positions");
    CHECK(mean < 1.5, "mean error %.2f", mean);
    CHECK(callbacks == positions, "callbacks %d positions %d", callbacks, positions);

    /* The latest position, then an out-of-order scan: rejected, engine unchanged. */
    waymark_position latest, again;
    CHECK(waymark_engine_position(engine, &latest) == WAYMARK_RESULT_OK, "position");
    waymark_wifi_reading old = {"02:00:00:00:00:00", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, 1, &old, 1, NULL, 0, NULL) == WAYMARK_RESULT_INPUT_REJECTED, "old scan");
    char message[256];
    size_t n = waymark_last_error(message, sizeof message);
    CHECK(n > 0 && strstr(message, "not after") != NULL, "last error: %s", message);
    CHECK(waymark_engine_position(engine, &again) == WAYMARK_RESULT_OK && again.timestamp_ns == latest.timestamp_ns,
          "unchanged");
    /* NaN samples are dropped, not fatal. */
    waymark_sample bad[2] = {{latest.timestamp_ns + 1, NAN, 0, 9.8}, {latest.timestamp_ns + 2, 0, 0, 9.8}};
    size_t accepted = 99;
    CHECK(waymark_engine_push_accelerometer(engine, bad, 2, &accepted) == WAYMARK_RESULT_OK && accepted == 1,
          "nan dropped, %zu accepted", accepted);
    /* Barometer readings: a NaN and one outside 300-1100 hPa are dropped and counted. */
    waymark_pressure_sample pressure[3] = {
        {latest.timestamp_ns + 1, 1000.0}, {latest.timestamp_ns + 2, NAN}, {latest.timestamp_ns + 3, 20000.0}};
    CHECK(waymark_engine_push_pressure(engine, pressure, 3, &accepted) == WAYMARK_RESULT_OK && accepted == 1,
          "pressure: %zu accepted", accepted);
    CHECK(waymark_engine_push_pressure(engine, NULL, 1, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL pressure");
    waymark_input_stats pressure_stats;
    CHECK(waymark_engine_input_stats(engine, &pressure_stats) == WAYMARK_RESULT_OK &&
              pressure_stats.pressure_dropped == 2,
          "pressure dropped %llu", (unsigned long long)pressure_stats.pressure_dropped);
    waymark_position moved;
    CHECK(waymark_engine_advance(engine, latest.timestamp_ns + 1500000000ull, &moved) == WAYMARK_RESULT_OK, "advance");
    /* A bad BSSID and a NaN RSSI are rejected. */
    waymark_wifi_reading junk = {"not-a-bssid", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, moved.timestamp_ns + 1, &junk, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED, "bad bssid");
    waymark_wifi_reading nan_rssi = {"02:00:00:00:00:00", NAN, 0};
    CHECK(waymark_engine_push_scan(engine, moved.timestamp_ns + 1, &nan_rssi, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED, "nan rssi");
    /* A panic inside Waymark (injected in this test build) is an error code, not an abort, and
     * the engine goes on. */
    waymark_wifi_reading known = {"02:00:00:00:00:00", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, UINT64_MAX - 7, &known, 1, NULL, 0, NULL) == WAYMARK_RESULT_PANIC,
          "injected panic");
    CHECK(waymark_engine_push_scan(engine, moved.timestamp_ns + 2, &known, 1, NULL, 0, NULL) == WAYMARK_RESULT_OK,
          "usable after a panic");
    /* A panic half-way through an epoch (injected at INT64_MAX - 8, after the engine has
     * stepped its filter and moved its clock) is undone: the same position, and no callback. */
    waymark_position kept, now;
    int heard = callbacks;
    CHECK(waymark_engine_position(engine, &kept) == WAYMARK_RESULT_OK, "position");
    CHECK(waymark_engine_push_scan(engine, INT64_MAX - 8, &known, 1, NULL, 0, NULL) == WAYMARK_RESULT_PANIC,
          "panic half-way through a scan");
    CHECK(waymark_engine_advance(engine, INT64_MAX - 8, NULL) == WAYMARK_RESULT_PANIC,
          "panic half-way through an advance");
    CHECK(waymark_engine_position(engine, &now) == WAYMARK_RESULT_OK && now.timestamp_ns == kept.timestamp_ns &&
              now.x == kept.x && now.y == kept.y && now.accuracy_m == kept.accuracy_m,
          "the undone epochs left the position");
    CHECK(callbacks == heard, "a callback for an undone epoch");
    CHECK(waymark_engine_push_scan(engine, kept.timestamp_ns + 1500000000ull, &known, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_OK && callbacks == heard + 1,
          "usable after a panic half-way");
    CHECK(waymark_engine_set_callback(engine, NULL, NULL) == WAYMARK_RESULT_OK, "clear callback");
    waymark_engine_free(engine);
}

static void error_paths(const char *site_path) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new(NULL, 0, &engine) == WAYMARK_RESULT_NULL_PARAMETER, "null json");
    CHECK(waymark_engine_new((const uint8_t *)"{}", 2, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null out");
    const char *bad = "{\"format_version\": 1, \"name\": ";
    CHECK(waymark_engine_new((const uint8_t *)bad, strlen(bad), &engine) == WAYMARK_RESULT_INVALID_SITE, "bad json");
    char message[256];
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "truncated") != NULL, "message: %s", message);
    CHECK(waymark_last_error(NULL, 0) > 0, "length query");
    CHECK(waymark_engine_new_from_path("/nonexistent/site.json", &engine) == WAYMARK_RESULT_INVALID_SITE, "no file");
    CHECK(waymark_engine_new_from_path(NULL, &engine) == WAYMARK_RESULT_NULL_PARAMETER, "null path");
    waymark_position p;
    CHECK(waymark_engine_position(NULL, &p) == WAYMARK_RESULT_NULL_PARAMETER, "null engine");
    CHECK(waymark_engine_push_accelerometer(NULL, NULL, 0, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null engine");
    waymark_engine_free(NULL);

    size_t len = 0;
    char *json = read_file(site_path, &len);
    CHECK(json != NULL, "read site");
    if (!json) return;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &engine) == WAYMARK_RESULT_OK, "site from bytes");
    CHECK(waymark_engine_position(engine, &p) == WAYMARK_RESULT_NO_POSITION, "no position yet");
    CHECK(waymark_engine_push_accelerometer(engine, NULL, 3, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "null samples");
    CHECK(waymark_engine_push_scan(engine, 5, NULL, 0, NULL, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED, "empty scan");
    CHECK(waymark_engine_push_scan(engine, 5, NULL, 2, NULL, 0, &p) == WAYMARK_RESULT_NULL_PARAMETER, "null wifi");
    waymark_beacon_reading beacon = {"fda50693-a4e2-4fb1-afcf-c6eb07647825", 1, 2, -70.0, 0, NULL};
    CHECK(waymark_engine_push_scan(engine, 5, NULL, 0, &beacon, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "unknown beacon only");
    free(json);
    waymark_engine_free(engine);
    CHECK(strcmp(waymark_version(), WAYMARK_VERSION) == 0, "version %s", waymark_version());
}

/* The binary encoding of the same site (`waymark site pack`): loads from bytes and from a path,
 * and a damaged copy is refused with a message that says so. */
static void binary_site(const char *packed_path) {
    size_t len = 0;
    char *bytes = read_file(packed_path, &len);
    CHECK(bytes != NULL && len > 16, "read packed site");
    if (!bytes) return;
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)bytes, len, &engine) == WAYMARK_RESULT_OK, "packed site from bytes");
    waymark_engine_free(engine);
    bytes[len / 2] ^= 0x40;
    engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)bytes, len, &engine) == WAYMARK_RESULT_INVALID_SITE && engine == NULL,
          "damaged packed site");
    char message[256];
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "damaged") != NULL, "message: %s", message);
    CHECK(waymark_engine_new((const uint8_t *)bytes, len - 1000, &engine) == WAYMARK_RESULT_INVALID_SITE,
          "cut packed site");
    free(bytes);
}

/* The site with its first access point turned into a BLE beacon known by its advertiser
 * address only (as Eddystone beacons are): a malloc'd copy of `json`, or NULL. */
static char *with_address_beacon(const char *json) {
    const char *wifi = "{\"wifi\":{\"bssid\":\"02:00:00:00:00:00\"}}";
    const char *ble = "{\"ble_address\":{\"mac\":\"02:00:00:00:00:00\"}}";
    const char *at = strstr(json, wifi);
    if (!at) return NULL;
    size_t head = (size_t)(at - json), len = strlen(json) - strlen(wifi) + strlen(ble);
    char *out = malloc(len + 1);
    if (!out) return NULL;
    memcpy(out, json, head);
    strcpy(out + head, ble);
    strcat(out, at + strlen(wifi));
    return out;
}

/* The site geo-referenced: an anchor in Helsinki (x east, y north) and its first floor at
 * level 2, inserted into `json`: a malloc'd copy, or NULL. */
static char *with_anchor(const char *json) {
    const char *floors = "\"floors\":", *anchor = "\"anchor\":{\"lat_deg\":60.17,\"lon_deg\":24.94},";
    const char *elevation = "\"elevation_m\":", *level = "\"level\":2,";
    const char *at = strstr(json, floors), *el = strstr(json, elevation);
    if (!at || !el || el < at) return NULL;
    char *out = malloc(strlen(json) + strlen(anchor) + strlen(level) + 1);
    if (!out) return NULL;
    size_t head = (size_t)(at - json), mid = (size_t)(el - at);
    memcpy(out, json, head);
    strcpy(out + head, anchor);
    strncat(out, at, mid);
    strcat(out, level);
    strcat(out, el);
    return out;
}

/* Positions carry latitude/longitude and the floor level only on a geo-referenced site, and a
 * fix in latitude/longitude is taken there and refused elsewhere. */
static void geo_reference(const char *site_path) {
    size_t len = 0;
    char *json = read_file(site_path, &len);
    char *site = json ? with_anchor(json) : NULL;
    CHECK(site != NULL, "the simulated site's floors");
    if (!site) { free(json); return; }
    waymark_engine *plain = NULL, *geo = NULL, *other = NULL;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &plain) == WAYMARK_RESULT_OK, "plain site");
    CHECK(waymark_engine_new((const uint8_t *)site, strlen(site), &geo) == WAYMARK_RESULT_OK, "anchored site");
    CHECK(waymark_engine_new((const uint8_t *)site, strlen(site), &other) == WAYMARK_RESULT_OK, "anchored site");
    free(json);
    free(site);
    waymark_position p, q;
    CHECK(waymark_engine_push_fix(plain, 1000000000ull, 35.5, 11.5, -1, 0.5, &p) == WAYMARK_RESULT_OK &&
              isnan(p.latitude_deg) && isnan(p.longitude_deg) && isnan(p.bearing_deg) && !p.has_floor_level,
          "no anchor: lat %g, level %d", p.latitude_deg, p.floor_level);
    CHECK(waymark_engine_push_fix_lat_lon(plain, 2000000000ull, 60.17, 24.94, -1, 0.5, &p) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "a lat/lon fix without an anchor");
    CHECK(waymark_engine_push_fix(geo, 1000000000ull, 35.5, 11.5, -1, 0.5, &p) == WAYMARK_RESULT_OK &&
              p.has_floor_level && p.floor_level == 2 && !p.level_unmapped,
          "anchored: level %d", p.floor_level);
    /* At 60°N a degree of latitude is 111 412 m and one of longitude 55 800 m (WGS84). */
    CHECK(fabs(p.latitude_deg - (60.17 + p.y / 111412.0)) < 1e-6 &&
              fabs(p.longitude_deg - (24.94 + p.x / 55800.0)) < 1e-5,
          "anchored: (%g, %g) at %.7f, %.7f", p.x, p.y, p.latitude_deg, p.longitude_deg);
    /* A fix at the estimate's latitude/longitude positions exactly as one at its x, y (on an
     * engine with the same history). */
    waymark_position r;
    CHECK(waymark_engine_push_fix(other, 1000000000ull, 35.5, 11.5, -1, 0.5, &r) == WAYMARK_RESULT_OK, "other");
    CHECK(waymark_engine_push_fix_lat_lon(geo, 2000000000ull, p.latitude_deg, p.longitude_deg, -1, 0.5, &q) ==
                  WAYMARK_RESULT_OK &&
              waymark_engine_push_fix(other, 2000000000ull, p.x, p.y, -1, 0.5, &r) == WAYMARK_RESULT_OK &&
              fabs(q.x - r.x) < 1e-6 && fabs(q.y - r.y) < 1e-6,
          "the same place in lat/lon: (%g, %g) and (%g, %g)", q.x, q.y, r.x, r.y);
    CHECK(waymark_engine_push_fix_lat_lon(geo, 3000000000ull, 91, 24.94, -1, 0.5, &q) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "latitude out of range");
    CHECK(waymark_engine_push_fix_lat_lon(NULL, 3000000000ull, 60.17, 24.94, -1, 0.5, &q) ==
              WAYMARK_RESULT_NULL_PARAMETER,
          "NULL engine");
    waymark_engine_free(plain);
    waymark_engine_free(geo);
    waymark_engine_free(other);
}

/* The lat/lon layers (docs/c.md#latitude-and-longitude): site points and a route's points to
 * latitude/longitude and back within a centimetre, geofences given as lat/lon polygons and
 * checked (a bow tie, a NaN vertex, a site without an anchor are refused). */
static void lat_lon_layers(const char *site_path) {
    size_t len = 0;
    char *json = read_file(site_path, &len);
    char *site = json ? with_anchor(json) : NULL;
    CHECK(site != NULL, "the simulated site's floors");
    if (!site) { free(json); return; }
    waymark_engine *plain = NULL, *geo = NULL;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &plain) == WAYMARK_RESULT_OK, "plain site");
    CHECK(waymark_engine_new((const uint8_t *)site, strlen(site), &geo) == WAYMARK_RESULT_OK, "anchored site");
    free(json);
    free(site);
    double lat = 0, lon = 0, x = 0, y = 0;
    const double points[][2] = {{0, 0}, {35.5, 11.5}, {-20, 400}};
    for (size_t k = 0; k < 3; k++) {
        CHECK(waymark_engine_to_lat_lon(geo, 0, points[k][0], points[k][1], &lat, &lon) == WAYMARK_RESULT_OK &&
                  waymark_engine_from_lat_lon(geo, 0, lat, lon, &x, &y) == WAYMARK_RESULT_OK &&
                  hypot(x - points[k][0], y - points[k][1]) < 0.01,
              "(%g, %g) came back as (%g, %g)", points[k][0], points[k][1], x, y);
    }
    CHECK(waymark_engine_to_lat_lon(geo, 0, 0, 100, &lat, &lon) == WAYMARK_RESULT_OK &&
              fabs(lat - (60.17 + 100 / 111412.0)) < 1e-6 && fabs(lon - 24.94) < 1e-9,
          "100 m north: %.7f, %.7f", lat, lon);
    CHECK(waymark_engine_to_lat_lon(plain, 0, 1, 1, &lat, &lon) == WAYMARK_RESULT_INPUT_REJECTED, "no anchor");
    CHECK(waymark_engine_to_lat_lon(geo, 0, NAN, 1, &lat, &lon) == WAYMARK_RESULT_INPUT_REJECTED, "NaN x");
    CHECK(waymark_engine_to_lat_lon(geo, 9, 1, 1, &lat, &lon) == WAYMARK_RESULT_INPUT_REJECTED, "no floor 9");
    CHECK(waymark_engine_to_lat_lon(geo, 0, 1, 1, NULL, &lon) == WAYMARK_RESULT_NULL_PARAMETER, "NULL out");
    CHECK(waymark_engine_from_lat_lon(geo, 0, 91, 24.94, &x, &y) == WAYMARK_RESULT_INPUT_REJECTED, "lat 91");
    CHECK(waymark_engine_from_lat_lon(plain, 0, 60.17, 24.94, &x, &y) == WAYMARK_RESULT_INPUT_REJECTED,
          "from lat/lon without an anchor");

    /* A route's legs in lat/lon, each end back within a centimetre; after the engine is gone
     * too (the route holds its site). */
    waymark_floor_point from = {0, 4.9, 2.0};
    waymark_route *route = NULL;
    CHECK(waymark_engine_route_to_zone(geo, &from, "room 10", &route) == WAYMARK_RESULT_OK && route, "route");
    waymark_route_info info;
    CHECK(waymark_route_get_info(route, &info) == WAYMARK_RESULT_OK && info.leg_count >= 3, "legs");
    for (size_t k = 0; k < info.leg_count; k++) {
        waymark_route_leg leg;
        CHECK(waymark_route_get_leg(route, k, &leg) == WAYMARK_RESULT_OK, "leg %zu", k);
        CHECK(waymark_route_to_lat_lon(route, &leg.end, &lat, &lon) == WAYMARK_RESULT_OK &&
                  waymark_engine_from_lat_lon(geo, leg.end.floor, lat, lon, &x, &y) == WAYMARK_RESULT_OK &&
                  hypot(x - leg.end.x, y - leg.end.y) < 0.01,
              "leg %zu's end (%g, %g) came back as (%g, %g)", k, leg.end.x, leg.end.y, x, y);
    }
    CHECK(waymark_route_to_lat_lon(route, NULL, &lat, &lon) == WAYMARK_RESULT_NULL_PARAMETER, "NULL point");

    /* The stair hall's square in lat/lon, closed as GeoJSON rings are: taken; the same as a
     * bow tie, with a NaN vertex, or on a site without an anchor: refused. */
    const double square[][2] = {{30, 8}, {40, 8}, {40, 15}, {30, 15}, {30, 8}};
    double ring[10], bowtie[8];
    for (size_t k = 0; k < 5; k++) {
        CHECK(waymark_engine_to_lat_lon(geo, 0, square[k][0], square[k][1], &ring[2 * k], &ring[2 * k + 1]) ==
                  WAYMARK_RESULT_OK,
              "vertex %zu", k);
    }
    CHECK(waymark_engine_add_geofence_polygon_lat_lon(geo, "hall", 0, ring, 5) == WAYMARK_RESULT_OK,
          "a lat/lon square");
    const size_t order[4] = {0, 2, 1, 3};
    for (size_t k = 0; k < 4; k++) {
        bowtie[2 * k] = ring[2 * order[k]];
        bowtie[2 * k + 1] = ring[2 * order[k] + 1];
    }
    CHECK(waymark_engine_add_geofence_polygon_lat_lon(geo, "bowtie", 0, bowtie, 4) == WAYMARK_RESULT_INPUT_REJECTED,
          "a self-intersecting ring");
    ring[3] = NAN;
    CHECK(waymark_engine_add_geofence_polygon_lat_lon(geo, "nan", 0, ring, 5) == WAYMARK_RESULT_INPUT_REJECTED,
          "a NaN vertex");
    CHECK(waymark_engine_add_geofence_polygon_lat_lon(geo, "null", 0, NULL, 3) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL vertices");
    CHECK(waymark_engine_add_geofence_polygon_lat_lon(plain, "plain", 0, bowtie, 4) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "a lat/lon geofence without an anchor");
    bool removed = false;
    CHECK(waymark_engine_remove_geofence(geo, "hall", &removed) == WAYMARK_RESULT_OK && removed, "hall was added");
    waymark_engine_free(plain);
    waymark_engine_free(geo);
    CHECK(waymark_route_to_lat_lon(route, &info.end, &lat, &lon) == WAYMARK_RESULT_OK, "the route outlives its engine");
    waymark_route_free(route);
}

static void address_beacons(const char *site_path) {
    size_t len = 0;
    char *json = read_file(site_path, &len);
    char *site = json ? with_address_beacon(json) : NULL;
    free(json);
    CHECK(site != NULL, "the simulated site's first access point");
    if (!site) return;
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)site, strlen(site), &engine) == WAYMARK_RESULT_OK, "site");
    free(site);
    const char *uuid = "fda50693-a4e2-4fb1-afcf-c6eb07647825";
    waymark_position p;
    /* By address: no UUID (NULL or empty), or an iBeacon left at major = minor = 0. */
    waymark_beacon_reading by_address = {.uuid = NULL, .rssi_dbm = -60.0, .address = "02-00-00-00-00-00"};
    CHECK(waymark_engine_push_scan(engine, 10, NULL, 0, &by_address, 1, &p) == WAYMARK_RESULT_OK, "address");
    CHECK(p.timestamp_ns == 10, "position at %llu", (unsigned long long)p.timestamp_ns);
    waymark_beacon_reading factory = {.uuid = uuid, .rssi_dbm = -60.0, .address = "02:00:00:00:00:00"};
    CHECK(waymark_engine_push_scan(engine, 20, NULL, 0, &factory, 1, &p) == WAYMARK_RESULT_OK, "0/0 iBeacon");
    /* The same address as an iBeacon with a major/minor is another, unknown, beacon. */
    waymark_beacon_reading ibeacon = {.uuid = uuid, .major = 1, .minor = 2, .rssi_dbm = -60.0,
                                      .address = "02:00:00:00:00:00"};
    CHECK(waymark_engine_push_scan(engine, 30, NULL, 0, &ibeacon, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "iBeacon");
    /* Bad input: an error code and a message, and the engine goes on. */
    const char *bad[] = {NULL, "", "02:00:00:00:00", "not a mac address"};
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        waymark_beacon_reading reading = {.uuid = "", .rssi_dbm = -60.0, .address = bad[i]};
        CHECK(waymark_engine_push_scan(engine, 30, NULL, 0, &reading, 1, &p) == WAYMARK_RESULT_INPUT_REJECTED,
              "bad address %zu", i);
        CHECK(waymark_last_error(NULL, 0) > 0, "message for bad address %zu", i);
    }
    by_address.uuid = "";
    CHECK(waymark_engine_push_scan(engine, 30, NULL, 0, &by_address, 1, &p) == WAYMARK_RESULT_OK, "goes on");
    waymark_engine_free(engine);
}

/* A hashed site: the right salt works, none or another is SALT_MISMATCH, a short one is
 * INVALID_CONFIG, and the message never holds the salt. */
static void salted(const char *hashed_path, const uint8_t *salt, size_t salt_len) {
    waymark_engine *engine = NULL;
    char message[512];
    CHECK(waymark_engine_new_from_path(hashed_path, &engine) == WAYMARK_RESULT_SALT_MISMATCH, "no salt");
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "salt") != NULL, "message: %s", message);
    CHECK(waymark_engine_new_from_path_with_salt(hashed_path, NULL, 0, &engine) == WAYMARK_RESULT_SALT_MISMATCH,
          "NULL salt");
    uint8_t wrong[32];
    memcpy(wrong, salt, sizeof wrong);
    wrong[0] ^= 1;
    CHECK(waymark_engine_new_from_path_with_salt(hashed_path, wrong, sizeof wrong, &engine) ==
              WAYMARK_RESULT_SALT_MISMATCH, "wrong salt");
    CHECK(waymark_engine_new_from_path_with_salt(hashed_path, salt, 8, &engine) == WAYMARK_RESULT_INVALID_CONFIG,
          "short salt");
    CHECK(waymark_engine_new_from_path_with_salt(hashed_path, NULL, 32, &engine) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL salt with a length");
    CHECK(waymark_engine_new_from_path_with_salt(hashed_path, salt, salt_len, NULL) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL out");
    CHECK(waymark_engine_new_from_path_with_salt(NULL, salt, salt_len, &engine) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL path");
    CHECK(waymark_engine_new_from_path_with_salt("\xff\xfe", salt, salt_len, &engine) == WAYMARK_RESULT_INVALID_UTF8,
          "path not UTF-8");
    CHECK(waymark_engine_new_with_salt(NULL, 10, salt, salt_len, &engine) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL json");

    size_t len = 0;
    char *json = read_file(hashed_path, &len);
    CHECK(json != NULL && strstr(json, "02:00:00") == NULL && strstr(json, "\"id_hash\"") != NULL,
          "the hashed file holds no BSSID");
    if (!json) return;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &engine) == WAYMARK_RESULT_SALT_MISMATCH, "bytes, no salt");
    CHECK(waymark_engine_new_with_salt((const uint8_t *)json, len, salt, salt_len, &engine) == WAYMARK_RESULT_OK,
          "bytes, salt");
    free(json);
    /* Scans carry raw BSSIDs, in any notation; the engine hashes them. */
    waymark_wifi_reading known[2] = {{"02:00:00:00:00:00", -60.0, 0}, {"02-00-00-00-00-01", -65.0, 0}};
    waymark_position p;
    CHECK(waymark_engine_push_scan(engine, 10, known, 2, NULL, 0, &p) == WAYMARK_RESULT_OK, "hashed match");
    waymark_wifi_reading unknown = {"aa:aa:aa:aa:aa:aa", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, 20, &unknown, 1, NULL, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "unknown through the hash");
    waymark_engine_free(engine);
}

/* Zones, user feedback and position fixes on the simulated office (ten rooms, the aisle and
 * the stair hall as zones). */
static void zones_and_feedback(const char *site_path) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new_from_path(site_path, &engine) == WAYMARK_RESULT_OK, "site");
    size_t zones = 0, name_len = 0;
    CHECK(waymark_engine_zone_count(engine, &zones) == WAYMARK_RESULT_OK && zones == 12, "%zu zones", zones);
    char name[64];
    CHECK(waymark_engine_zone_name(engine, 0, name, sizeof name, &name_len) == WAYMARK_RESULT_OK &&
              strcmp(name, "aisle") == 0 && name_len == 5,
          "zone 0 is %s", name);
    char small[4];
    CHECK(waymark_engine_zone_name(engine, 11, small, sizeof small, &name_len) == WAYMARK_RESULT_OK &&
              strcmp(small, "sta") == 0 && name_len == strlen("stair hall"),
          "truncated name %s (%zu)", small, name_len);
    CHECK(waymark_engine_zone_name(engine, 12, name, sizeof name, NULL) == WAYMARK_RESULT_INPUT_REJECTED,
          "zone index out of range");
    CHECK(waymark_engine_zone_name(engine, 0, NULL, 8, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL buffer");
    CHECK(waymark_engine_zone_count(engine, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL count");

    waymark_wifi_reading known[2] = {{"02:00:00:00:00:00", -60.0, 0}, {"02:00:00:00:00:01", -70.0, 0}};
    waymark_position p;
    CHECK(waymark_engine_push_scan(engine, 10, known, 2, NULL, 0, &p) == WAYMARK_RESULT_OK, "scan");
    CHECK(p.zone >= -1 && p.zone < 12 && p.zone_probability >= 0 && p.zone_probability <= 1 + 1e-9,
          "zone %d (%g)", p.zone, p.zone_probability);
    double posterior[12], sum = 0;
    CHECK(waymark_engine_zone_posterior(engine, posterior, 12) == WAYMARK_RESULT_OK, "zone posterior");
    for (int z = 0; z < 12; z++) sum += posterior[z];
    CHECK(sum > 0 && sum <= 1 + 1e-9, "zone posterior sums to %g", sum);
    CHECK(waymark_engine_zone_posterior(engine, NULL, 3) == WAYMARK_RESULT_NULL_PARAMETER, "NULL posterior");

    /* "I am in room 3", about the position just shown: that epoch is pinned to the room. */
    CHECK(waymark_engine_confirm_zone(engine, 10, "room 3", &p) == WAYMARK_RESULT_OK && p.zone == 3 &&
              fabs(p.zone_probability - 1) < 1e-9 && p.timestamp_ns == 10,
          "confirmed room: zone %d (%g)", p.zone, p.zone_probability);
    CHECK(waymark_engine_confirm_zone(engine, 20, "cellar", &p) == WAYMARK_RESULT_INPUT_REJECTED, "unknown zone");
    char message[256];
    waymark_last_error(message, sizeof message);
    CHECK(strstr(message, "cellar") != NULL, "message: %s", message);
    CHECK(waymark_engine_confirm_zone(engine, 5, "room 3", &p) == WAYMARK_RESULT_INPUT_REJECTED, "back in time");
    CHECK(waymark_engine_confirm_zone(engine, 20, NULL, &p) == WAYMARK_RESULT_NULL_PARAMETER, "NULL zone");
    /* "I am within 2 m of here": the aisle's first state is at (1.7, 11.5). */
    CHECK(waymark_engine_confirm_position(engine, 30000000000ull, 1.7, 11.5, 0, 2.0, &p) == WAYMARK_RESULT_OK &&
              p.zone == 0 && fabs(p.x - 1.7) < 1e-9,
          "confirmed position (%g, %g), zone %d", p.x, p.y, p.zone);
    CHECK(waymark_engine_confirm_position(engine, 40000000000ull, 1.7, 11.5, 3, 2.0, &p) ==
              WAYMARK_RESULT_INPUT_REJECTED, "unknown floor");
    CHECK(waymark_engine_confirm_position(engine, 40000000000ull, 500, 500, 0, 2.0, &p) ==
              WAYMARK_RESULT_INPUT_REJECTED, "no state within the radius");
    /* A precise fix 40 s later (time to walk there) at the stair hall's middle state (35.5,
     * 11.5) takes the estimate there; bad fixes are rejected and change nothing. */
    CHECK(waymark_engine_push_fix(engine, 70000000000ull, 35.5, 11.5, -1, 0.5, &p) == WAYMARK_RESULT_OK &&
              hypot(p.x - 35.5, p.y - 11.5) < 1.0 && p.zone == 11,
          "fix: (%g, %g), zone %d", p.x, p.y, p.zone);
    waymark_position kept, now;
    CHECK(waymark_engine_position(engine, &kept) == WAYMARK_RESULT_OK, "position");
    CHECK(waymark_engine_push_fix(engine, 80000000000ull, NAN, 11.5, -1, 3, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "NaN fix");
    CHECK(waymark_engine_push_fix(engine, 80000000000ull, 35.5, 11.5, -1, 0, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "zero accuracy");
    CHECK(waymark_engine_push_fix(engine, 80000000000ull, 35.5, 11.5, 4, 3, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "unknown floor");
    CHECK(waymark_engine_push_fix(engine, 80000000000ull, 3000, 11.5, -1, 3, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "far outside the site");
    CHECK(waymark_engine_push_fix(engine, 40000000000ull, 35.5, 11.5, 0, 3, &p) == WAYMARK_RESULT_INPUT_REJECTED,
          "not after the last epoch");
    CHECK(waymark_engine_position(engine, &now) == WAYMARK_RESULT_OK && now.timestamp_ns == kept.timestamp_ns &&
              now.x == kept.x && now.zone == kept.zone,
          "rejected fixes changed nothing");
    waymark_engine_free(engine);
}

/* The walk again, with a position fix 1.5 m east and 0.5 m north of the truth just after
 * every third position, and the user confirming where they are after every seventh: the
 * history habits are learned from. Counts the accepted fixes and confirmations. */
/* Called after each scan the engine accepted during `replay`, with the epoch's truth. */
typedef void (*accepted_scan)(waymark_engine *engine, unsigned long long t, double tx, double ty,
                              const waymark_position *p, void *context);

/* Replays the walk's IMU batches and scans into `engine`, calling `hook` after each accepted scan. */
static void replay(waymark_engine *engine, const char *walk_path, accepted_scan hook, void *context) {
    FILE *f = fopen(walk_path, "r");
    CHECK(f != NULL, "open walk");
    if (!f) return;
    unsigned long long t;
    double tx, ty;
    size_t na, ng, nm, nw;
    while (fscanf(f, " E %llu %lf %lf %zu %zu %zu %zu", &t, &tx, &ty, &na, &ng, &nm, &nw) == 7) {
        waymark_sample *a = read_samples(f, na), *g = read_samples(f, ng), *m = read_samples(f, nm);
        waymark_engine_push_accelerometer(engine, a, na, NULL);
        waymark_engine_push_gyroscope(engine, g, ng, NULL);
        waymark_engine_push_magnetometer(engine, m, nm, NULL);
        free(a);
        free(g);
        free(m);
        char (*bssids)[32] = NULL;
        waymark_wifi_reading *w = read_scan(f, nw, &bssids);
        waymark_position p;
        if (waymark_engine_push_scan(engine, t, w, nw, NULL, 0, &p) == WAYMARK_RESULT_OK)
            hook(engine, t, tx, ty, &p, context);
        free(w);
        free(bssids);
    }
    fclose(f);
}

/* Counts the scans the engine accepted during `replay`. */
static void counted(waymark_engine *engine, unsigned long long t, double tx, double ty, const waymark_position *p,
                    void *context) {
    (void)engine, (void)t, (void)tx, (void)ty, (void)p;
    ++*(int *)context;
}

/* Map evidence from the session (taken, freed twice, stopped) and a refitted site loaded in
 * place: the same site in its binary encoding carries the session on; a file that is not a
 * site, or a hashed site without its salt, changes nothing. */
static void session_evidence(const char *site_path, const char *walk_path, const char *hashed_path,
                             const char *packed_path) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new_from_path(site_path, &engine) == WAYMARK_RESULT_OK, "site");
    if (!engine) return;
    waymark_evidence none = {0};
    CHECK(waymark_engine_take_evidence(engine, &none) == WAYMARK_RESULT_OK && none.bytes == NULL && none.len == 0,
          "nothing taken before gathering starts");
    CHECK(waymark_engine_take_evidence(engine, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "take into NULL");
    CHECK(waymark_engine_start_evidence(engine) == WAYMARK_RESULT_OK, "start evidence");
    int accepted = 0;
    replay(engine, walk_path, counted, &accepted);
    waymark_evidence taken = {0};
    CHECK(waymark_engine_take_evidence(engine, &taken) == WAYMARK_RESULT_OK, "take evidence");
    CHECK(taken.bytes != NULL && taken.len > 16 && memcmp(taken.bytes, "WMEV", 4) == 0, "evidence bytes (%zu)",
          taken.len);
    CHECK(accepted > 10 && taken.scans == (uint64_t)accepted && taken.scans_dropped == 0,
          "every accepted scan is in the evidence: %d accepted, %llu in it, %llu dropped", accepted,
          (unsigned long long)taken.scans, (unsigned long long)taken.scans_dropped);
    waymark_evidence_free(&taken);
    CHECK(taken.bytes == NULL && taken.len == 0, "freed evidence is emptied");
    waymark_evidence_free(&taken);
    waymark_evidence_free(NULL);
    waymark_evidence again = {0};
    CHECK(waymark_engine_take_evidence(engine, &again) == WAYMARK_RESULT_OK && again.bytes != NULL && again.scans == 0,
          "gathering goes on from nothing");
    waymark_evidence_free(&again);
    waymark_position before, after;
    CHECK(waymark_engine_position(engine, &before) == WAYMARK_RESULT_OK, "position");

    size_t len = 0;
    char *bytes = read_file(packed_path, &len);
    CHECK(bytes != NULL, "read %s", packed_path);
    waymark_evidence old = {0};
    CHECK(waymark_engine_replace_site(engine, (const uint8_t *)bytes, len, &old) == WAYMARK_RESULT_OK,
          "the same site, binary, in place");
    CHECK(old.bytes != NULL && old.scans == 0, "what the old site gathered since the take");
    waymark_evidence_free(&old);
    CHECK(waymark_engine_position(engine, &after) == WAYMARK_RESULT_OK && after.timestamp_ns == before.timestamp_ns &&
              after.x == before.x && after.y == before.y,
          "the session carries on");
    CHECK(waymark_engine_stop_evidence(engine) == WAYMARK_RESULT_OK, "stop evidence");
    CHECK(waymark_engine_replace_site(engine, (const uint8_t *)bytes, len, NULL) == WAYMARK_RESULT_OK,
          "replaced again, no evidence wanted");
    free(bytes);

    const char junk[] = "{\"not\": \"a site\"}";
    CHECK(waymark_engine_replace_site(engine, (const uint8_t *)junk, sizeof junk - 1, &old) ==
              WAYMARK_RESULT_INVALID_SITE,
          "not a site");
    CHECK(waymark_engine_replace_site(engine, NULL, 0, &old) == WAYMARK_RESULT_NULL_PARAMETER, "NULL site");
    char *hashed = read_file(hashed_path, &len);
    CHECK(hashed != NULL, "read %s", hashed_path);
    CHECK(waymark_engine_replace_site(engine, (const uint8_t *)hashed, len, &old) == WAYMARK_RESULT_SALT_MISMATCH,
          "a hashed site without its salt");
    free(hashed);
    CHECK(waymark_engine_position(engine, &after) == WAYMARK_RESULT_OK && after.timestamp_ns == before.timestamp_ns &&
              after.x == before.x,
          "refused sites change nothing");
    CHECK(waymark_engine_replace_site(NULL, (const uint8_t *)junk, sizeof junk - 1, &old) ==
              WAYMARK_RESULT_NULL_PARAMETER,
          "NULL engine");
    CHECK(waymark_engine_start_evidence(NULL) == WAYMARK_RESULT_NULL_PARAMETER, "start on NULL");
    waymark_engine_free(engine);
}

/* Fixes and confirmations pushed, and positions seen, by `with_fixes`. */
typedef struct {
    int positions, fixes, confirmations;
} fixed;

/* Confirms some positions at the truth and pushes fixes 1.5 m east and 0.5 m north of it. */
static void with_fixes(waymark_engine *engine, unsigned long long t, double tx, double ty,
                       const waymark_position *p, void *context) {
    (void)p;
    fixed *c = context;
    c->positions++;
    if (c->positions % 7 == 3 && waymark_engine_confirm_position(engine, t, tx, ty, 0, 1.5, NULL) == WAYMARK_RESULT_OK)
        c->confirmations++;
    if (c->positions % 3 == 1 &&
        waymark_engine_push_fix(engine, t + 1000, tx + 1.5, ty + 0.5, 0, 2.0, NULL) == WAYMARK_RESULT_OK)
        c->fixes++;
}

/* Habits: learned from a walk, exported (the buffer protocol), imported into a second engine,
 * refused models leave the engine unchanged, cleared. */
static void habits(const char *site_path, const char *walk_path) {
    waymark_engine *engine = NULL, *other = NULL;
    CHECK(waymark_engine_new_from_path(site_path, &engine) == WAYMARK_RESULT_OK, "site");
    CHECK(waymark_engine_new_from_path(site_path, &other) == WAYMARK_RESULT_OK, "second engine");
    waymark_fix_bias e = {NAN, NAN, NAN};
    CHECK(waymark_engine_fix_bias(engine, &e) == WAYMARK_RESULT_OK && e.bias_x_m == 0 && e.bias_y_m == 0 &&
              e.spread == 1,
          "nothing learned yet: bias (%g, %g) spread %g", e.bias_x_m, e.bias_y_m, e.spread);
    fixed pushed = {0};
    replay(engine, walk_path, with_fixes, &pushed);
    int fixes = pushed.fixes, confirmations = pushed.confirmations;
    CHECK(fixes > 5 && confirmations > 2, "%d fixes, %d confirmations", fixes, confirmations);

    waymark_habit_report r;
    memset(&r, 0xff, sizeof r);
    CHECK(waymark_engine_learn_habits(engine, &r) == WAYMARK_RESULT_OK, "learn");
    printf("habits: %zu epochs, %zu transitions, applied %d\n", r.epochs, r.learned_transitions, (int)r.applied);
    CHECK(r.epochs > 10, "report: %zu epochs", r.epochs);
    CHECK(r.learned_transitions > 0 && r.total_epochs == r.epochs, "%zu transitions", r.learned_transitions);
    /* 1.5 m east, 0.5 m north, shrunk toward 0 by the prior's 5 pseudo-fixes. */
    CHECK(waymark_engine_fix_bias(engine, &e) == WAYMARK_RESULT_OK && e.bias_x_m > 0.3 && e.bias_y_m > 0 &&
              e.bias_x_m > e.bias_y_m && e.spread > 0,
          "learned bias (%g, %g)", e.bias_x_m, e.bias_y_m);
    waymark_fix_bias learned = e;
    /* Each epoch once: nothing new to learn. */
    waymark_habit_report again;
    CHECK(waymark_engine_learn_habits(engine, &again) == WAYMARK_RESULT_OK && again.epochs == 0 &&
              again.total_epochs == r.total_epochs && again.applied == r.applied,
          "second pass: %zu epochs", again.epochs);
    CHECK(waymark_engine_learn_habits(engine, NULL) == WAYMARK_RESULT_OK, "NULL report");

    /* Export: ask the length, a buffer one byte short, then the right size. */
    size_t json_len = 0, empty_len = 0;
    CHECK(waymark_engine_export_habits(engine, NULL, 0, &json_len) == WAYMARK_RESULT_BUFFER_TOO_SMALL &&
              json_len > 100,
          "length query: %zu", json_len);
    char *json = malloc(json_len + 1);
    memset(json, 'x', json_len + 1);
    size_t got = 0;
    CHECK(waymark_engine_export_habits(engine, json, json_len, &got) == WAYMARK_RESULT_BUFFER_TOO_SMALL &&
              got == json_len && json[0] == 0 && json[1] == 'x',
          "one byte short: an empty string, no truncated JSON");
    CHECK(waymark_last_error(NULL, 0) > 0, "message for a short buffer");
    CHECK(waymark_engine_export_habits(engine, json, json_len + 1, &got) == WAYMARK_RESULT_OK &&
              strlen(json) == json_len && strstr(json, "\"waymark-habits\"") != NULL,
          "export");
    CHECK(waymark_engine_export_habits(engine, NULL, 8, &got) == WAYMARK_RESULT_NULL_PARAMETER, "NULL buffer");
    CHECK(waymark_engine_export_habits(NULL, json, json_len + 1, &got) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL engine");

    /* Into the second engine: the same model. */
    CHECK(waymark_engine_export_habits(other, NULL, 0, &empty_len) == WAYMARK_RESULT_BUFFER_TOO_SMALL, "length");
    char *empty = malloc(empty_len + 1);
    CHECK(waymark_engine_export_habits(other, empty, empty_len + 1, NULL) == WAYMARK_RESULT_OK, "empty export");
    CHECK(waymark_engine_import_habits(other, json) == WAYMARK_RESULT_OK, "import");
    char *back = malloc(json_len + 1);
    CHECK(waymark_engine_export_habits(other, back, json_len + 1, &got) == WAYMARK_RESULT_OK &&
              strcmp(back, json) == 0,
          "imported model exports the same JSON");
    CHECK(waymark_engine_fix_bias(other, &e) == WAYMARK_RESULT_OK && e.bias_x_m == learned.bias_x_m,
          "imported fix error");

    /* Refused models: HABITS_REJECTED (or a typed argument error), and nothing changes. */
    char *wrong_site = malloc(json_len + 1);
    strcpy(wrong_site, json);
    char *digest = strstr(wrong_site, "\"digest\":\"");
    CHECK(digest != NULL, "a digest in the export");
    if (digest) digest[10] = digest[10] == '0' ? '1' : '0';
    char *negative = malloc(json_len + 8);
    const char *count = strstr(json, "\"count\":[");
    CHECK(count != NULL, "a learned count in the export");
    if (count) {
        size_t head = (size_t)(count - json) + strlen("\"count\":[");
        memcpy(negative, json, head);
        strcpy(negative + head, "-1,");
        strcat(negative, json + head);
    }
    const char *rejected[] = {"", "{", "null", "[]", "{\"format\":\"waymark-site\",\"version\":1}",
                              "{\"format\":\"waymark-habits\",\"version\":99}", wrong_site, negative};
    for (size_t i = 0; i < sizeof rejected / sizeof *rejected; i++) {
        CHECK(waymark_engine_import_habits(other, rejected[i]) == WAYMARK_RESULT_HABITS_REJECTED,
              "refused model %zu", i);
        char message[256];
        CHECK(waymark_last_error(message, sizeof message) > 0, "message for refused model %zu", i);
        if (i == 6) CHECK(strstr(message, "another site") != NULL, "wrong site: %s", message);
        CHECK(waymark_engine_export_habits(other, back, json_len + 1, &got) == WAYMARK_RESULT_OK &&
                  strcmp(back, json) == 0,
              "refused model %zu changed the habits", i);
    }
    CHECK(waymark_engine_import_habits(other, "\xff\xfe") == WAYMARK_RESULT_INVALID_UTF8, "not UTF-8");
    CHECK(waymark_engine_import_habits(other, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL json");
    CHECK(waymark_engine_import_habits(NULL, json) == WAYMARK_RESULT_NULL_PARAMETER, "NULL engine");
    CHECK(waymark_engine_export_habits(other, back, json_len + 1, &got) == WAYMARK_RESULT_OK &&
              strcmp(back, json) == 0,
          "bad arguments changed the habits");

    /* Cleared: the empty model again. */
    CHECK(waymark_engine_clear_habits(other) == WAYMARK_RESULT_OK, "clear");
    CHECK(waymark_engine_export_habits(other, back, json_len + 1, &got) == WAYMARK_RESULT_OK &&
              strcmp(back, empty) == 0,
          "cleared");
    CHECK(waymark_engine_fix_bias(other, &e) == WAYMARK_RESULT_OK && e.bias_x_m == 0 && e.spread == 1,
          "cleared fix error");
    CHECK(waymark_engine_clear_habits(NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL engine");
    CHECK(waymark_engine_learn_habits(NULL, &r) == WAYMARK_RESULT_NULL_PARAMETER, "NULL engine");
    CHECK(waymark_engine_fix_bias(NULL, &e) == WAYMARK_RESULT_NULL_PARAMETER, "NULL engine");
    CHECK(waymark_engine_fix_bias(other, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL out");
    free(json);
    free(empty);
    free(back);
    free(wrong_site);
    free(negative);
    waymark_engine_free(engine);
    waymark_engine_free(other);
}

/* Zone and geofence events through the status callback. */
typedef struct {
    int zone_entered, zone_exited, fence_entered, fence_exited;
    char last_zone[32], last_fence[32];
} presence;

static void on_presence(void *userdata, const waymark_status *status) {
    presence *s = userdata;
    switch (status->kind) {
    case WAYMARK_STATUS_KIND_ZONE_ENTERED:
    case WAYMARK_STATUS_KIND_ZONE_EXITED:
        if (status->kind == WAYMARK_STATUS_KIND_ZONE_ENTERED) s->zone_entered++; else s->zone_exited++;
        snprintf(s->last_zone, sizeof s->last_zone, "%d %s", status->zone, status->name ? status->name : "");
        break;
    case WAYMARK_STATUS_KIND_GEOFENCE_ENTERED:
    case WAYMARK_STATUS_KIND_GEOFENCE_EXITED:
        if (status->kind == WAYMARK_STATUS_KIND_GEOFENCE_ENTERED) s->fence_entered++; else s->fence_exited++;
        snprintf(s->last_fence, sizeof s->last_fence, "%s", status->name ? status->name : "");
        break;
    default: break;
    }
}

static void geofences_and_zone_events(const char *site_path) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new_from_path(site_path, &engine) == WAYMARK_RESULT_OK, "site");
    presence heard = {0};
    CHECK(waymark_engine_set_status_callback(engine, on_presence, &heard) == WAYMARK_RESULT_OK, "callback");
    /* Around the aisle's first state, (1.7, 11.5). */
    CHECK(waymark_engine_add_geofence_circle(engine, "entrance", 0, 1.7, 11.5, 3.0) == WAYMARK_RESULT_OK, "circle");
    CHECK(waymark_engine_add_geofence_circle(engine, "entrance", 0, 1.7, 11.5, 3.0) ==
              WAYMARK_RESULT_INPUT_REJECTED, "a taken id");
    CHECK(waymark_engine_add_geofence_circle(engine, NULL, 0, 1.7, 11.5, 3.0) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL id");
    CHECK(waymark_engine_add_geofence_circle(engine, "nan", 0, NAN, 11.5, 3.0) == WAYMARK_RESULT_INPUT_REJECTED,
          "NaN centre");
    double stairs[] = {33.0, 9.0, 38.0, 9.0, 38.0, 14.0, 33.0, 14.0};
    CHECK(waymark_engine_add_geofence_polygon(engine, "stairs", 0, stairs, 4) == WAYMARK_RESULT_OK, "polygon");
    CHECK(waymark_engine_add_geofence_polygon(engine, "line", 0, stairs, 2) == WAYMARK_RESULT_INPUT_REJECTED,
          "two vertices");
    CHECK(waymark_engine_add_geofence_polygon(engine, "null", 0, NULL, 3) == WAYMARK_RESULT_NULL_PARAMETER,
          "NULL vertices");

    waymark_wifi_reading known[2] = {{"02:00:00:00:00:00", -60.0, 0}, {"02:00:00:00:00:01", -70.0, 0}};
    waymark_position p;
    CHECK(waymark_engine_push_scan(engine, 10, known, 2, NULL, 0, &p) == WAYMARK_RESULT_OK, "scan");
    /* Pinned at the entrance, then at the stair hall 40 s later: in, out, in. */
    CHECK(waymark_engine_confirm_position(engine, 10, 1.7, 11.5, 0, 1.0, &p) == WAYMARK_RESULT_OK, "at the door");
    CHECK(heard.fence_entered == 1 && strcmp(heard.last_fence, "entrance") == 0, "entered %d %s",
          heard.fence_entered, heard.last_fence);
    CHECK(heard.zone_entered >= 1 && strcmp(heard.last_zone, "0 aisle") == 0, "zone %s", heard.last_zone);
    CHECK(waymark_engine_confirm_position(engine, 40000000000ull, 35.5, 11.5, 0, 1.0, &p) == WAYMARK_RESULT_OK,
          "at the stairs");
    CHECK(heard.fence_exited == 1 && heard.fence_entered == 2 && strcmp(heard.last_fence, "stairs") == 0,
          "left the entrance for the stairs: %d %d %s", heard.fence_exited, heard.fence_entered, heard.last_fence);
    CHECK(heard.zone_exited >= 1 && strcmp(heard.last_zone, "11 stair hall") == 0, "zone %s", heard.last_zone);
    bool removed = false;
    CHECK(waymark_engine_remove_geofence(engine, "stairs", &removed) == WAYMARK_RESULT_OK && removed, "removed");
    CHECK(waymark_engine_remove_geofence(engine, "stairs", &removed) == WAYMARK_RESULT_OK && !removed,
          "removed once");
    waymark_engine_free(engine);
}

/* Routes (docs/routes.md) on the simulated office: room 1's far corner to room 10 as legs,
 * a tracker that notices a detour and reroutes, typed errors (no position, unknown zone, off
 * the graph, NULLs), and the route outliving its engine. */
static void routes(const char *site_path) {
    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new_from_path(site_path, &engine) == WAYMARK_RESULT_OK, "site");
    waymark_floor_point from = {0, 4.9, 2.0};
    waymark_route *route = NULL;
    CHECK(waymark_engine_route_to_zone(engine, &from, "room 10", &route) == WAYMARK_RESULT_OK && route, "route");
    waymark_route_info info;
    CHECK(waymark_route_get_info(route, &info) == WAYMARK_RESULT_OK && info.leg_count >= 3, "%zu legs",
          info.leg_count);
    double sum = 0;
    for (size_t k = 0; k < info.leg_count; k++) {
        waymark_route_leg leg;
        CHECK(waymark_route_get_leg(route, k, &leg) == WAYMARK_RESULT_OK && leg.distance_m >= 0, "leg %zu", k);
        sum += leg.distance_m;
    }
    CHECK(fabs(sum - info.length_m) < 1e-9, "legs sum to %g, route %g", sum, info.length_m);
    CHECK(info.length_m >= hypot(info.end.x - info.start.x, info.end.y - info.start.y), "never under the line");
    waymark_route_leg leg;
    CHECK(waymark_route_get_leg(route, 1, &leg) == WAYMARK_RESULT_OK && leg.turn != WAYMARK_TURN_NONE,
          "the second leg starts with a turn");
    CHECK(waymark_route_get_leg(route, info.leg_count, &leg) == WAYMARK_RESULT_INPUT_REJECTED, "leg out of range");
    CHECK(waymark_route_get_info(NULL, &info) == WAYMARK_RESULT_NULL_PARAMETER, "NULL route");
    waymark_route_progress progress;
    CHECK(waymark_route_update(route, &info.start, 2.0, &progress) == WAYMARK_RESULT_OK && !progress.off_route &&
              fabs(progress.remaining_m - info.length_m) < 1e-9,
          "at the start: %g left", progress.remaining_m);
    /* Deep in room 2, off the aisle. */
    waymark_floor_point detour = {0, 10.0, 3.0};
    CHECK(waymark_route_update(route, &detour, 2.0, &progress) == WAYMARK_RESULT_OK && progress.off_route,
          "a detour is off the route");
    waymark_floor_point nowhere = {0, NAN, 0.0};
    CHECK(waymark_route_update(route, &nowhere, 2.0, NULL) == WAYMARK_RESULT_OFF_GRAPH, "a NaN position");
    CHECK(waymark_route_reroute(route, &detour) == WAYMARK_RESULT_OK, "reroute");
    CHECK(waymark_route_update(route, &detour, 2.0, &progress) == WAYMARK_RESULT_OK && !progress.off_route,
          "on the new route");
    waymark_route *none = NULL;
    /* No position yet: a route from it is refused. */
    CHECK(waymark_engine_route_to_zone(engine, NULL, "room 10", &none) == WAYMARK_RESULT_NO_POSITION && !none,
          "no position");
    CHECK(waymark_engine_route_to_zone(engine, &from, "kitchen", &none) == WAYMARK_RESULT_UNKNOWN_ZONE && !none,
          "unknown zone");
    waymark_floor_point upstairs = {7, 1.0, 1.0};
    CHECK(waymark_engine_route_to_point(engine, &upstairs, &from, &none) == WAYMARK_RESULT_OFF_GRAPH && !none,
          "no floor 7");
    waymark_floor_point far = {0, 500.0, 0.0};
    CHECK(waymark_engine_route_to_point(engine, &from, &far, &none) == WAYMARK_RESULT_OFF_GRAPH && !none,
          "500 m off the office");
    CHECK(waymark_engine_route_to_zone(engine, &from, NULL, &none) == WAYMARK_RESULT_NULL_PARAMETER, "NULL zone");
    CHECK(waymark_engine_route_to_point(engine, &from, NULL, &none) == WAYMARK_RESULT_NULL_PARAMETER, "NULL point");
    waymark_engine_free(engine);
    /* The route keeps its own reference to the site. */
    CHECK(waymark_route_get_info(route, &info) == WAYMARK_RESULT_OK, "after the engine is freed");
    waymark_route_free(route);
    waymark_route_free(NULL);
}

/* What the status callback heard. */
typedef struct {
    int no_coverage, errors, other;
    waymark_result last_error;
    char message[128];
} statuses;

static void on_status(void *userdata, const waymark_status *status) {
    statuses *s = userdata;
    switch (status->kind) {
    case WAYMARK_STATUS_KIND_NO_SITE_COVERAGE: s->no_coverage++; break;
    case WAYMARK_STATUS_KIND_ERROR:
        s->errors++;
        s->last_error = status->error;
        snprintf(s->message, sizeof s->message, "%s", status->message ? status->message : "");
        break;
    default: s->other++; break;
    }
}

static int log_records = 0;
static void on_log(void *userdata, uint32_t level, const char *target, const char *message) {
    (void)userdata;
    if (level >= WAYMARK_LOG_LEVEL_ERROR && level <= WAYMARK_LOG_LEVEL_TRACE && target && message) log_records++;
}

/* The options struct and its defaults, the status callback, the log hook, the input statistics,
 * the version, and an engine a panic left unusable: every getter then fails with a code. */
static void options_status_and_stats(const char *site_path) {
    CHECK(strcmp(waymark_version(), WAYMARK_VERSION) == 0, "version %s", waymark_version());
    CHECK(waymark_set_log_callback(WAYMARK_LOG_LEVEL_WARN, on_log, NULL) == WAYMARK_RESULT_OK, "log hook");
    CHECK(waymark_set_log_callback(42, on_log, NULL) == WAYMARK_RESULT_INVALID_CONFIG, "no such log level");
    waymark_engine_options options;
    CHECK(waymark_engine_options_default(NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL options");
    CHECK(waymark_engine_options_default(&options) == WAYMARK_RESULT_OK && options.transition == 0 &&
              options.fixed_lag_epochs > 0 && isnan(options.step_length_m) && isnan(options.declination_deg) &&
              options.site_salt == NULL,
          "default options");
    size_t len = 0;
    char *json = read_file(site_path, &len);
    CHECK(json != NULL, "read site");
    if (!json) return;
    waymark_engine *engine = NULL;
    options.transition = 7;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
              WAYMARK_RESULT_INVALID_CONFIG && engine == NULL,
          "no such transition model");
    options.transition = WAYMARK_TRANSITION_HIPE;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) == WAYMARK_RESULT_OK,
          "engine with options");
    waymark_engine *defaults = NULL;
    CHECK(waymark_engine_new_with_options((const uint8_t *)json, len, NULL, &defaults) == WAYMARK_RESULT_OK,
          "NULL options: the defaults");
    waymark_engine_free(defaults);
    free(json);

    statuses heard = {0};
    CHECK(waymark_engine_set_status_callback(engine, on_status, &heard) == WAYMARK_RESULT_OK, "status callback");
    waymark_wifi_reading unknown = {"0a:0b:0c:0d:0e:0f", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, 1000000000ull, &unknown, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "a scan of no known transmitter");
    CHECK(heard.no_coverage == 1 && heard.errors == 1 && heard.last_error == WAYMARK_RESULT_INPUT_REJECTED &&
              strlen(heard.message) > 0,
          "status: %d no coverage, %d errors (%u: %s)", heard.no_coverage, heard.errors, heard.last_error,
          heard.message);
    waymark_wifi_reading known = {"02:00:00:00:00:00", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, 2000000000ull, &known, 1, NULL, 0, NULL) == WAYMARK_RESULT_OK, "scan");
    waymark_input_stats stats;
    CHECK(waymark_engine_input_stats(engine, NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL stats");
    CHECK(waymark_engine_input_stats(engine, &stats) == WAYMARK_RESULT_OK && stats.scans_accepted == 1 &&
              stats.scans_no_known_transmitter == 1,
          "stats: %llu accepted, %llu of no known transmitter", (unsigned long long)stats.scans_accepted,
          (unsigned long long)stats.scans_no_known_transmitter);

    /* A panic half-way through a change the engine cannot undo (injected in this test build)
     * leaves it unusable: every later call, getters included, returns PANIC and writes nothing. */
    CHECK(waymark_engine_import_habits(engine, "waymark fault injection") == WAYMARK_RESULT_PANIC,
          "injected panic while importing");
    size_t json_len = 12345, zones = 0;
    double posterior[1] = {-1.0};
    waymark_fix_bias fix = {-1.0, -1.0, -1.0};
    CHECK(waymark_engine_export_habits(engine, NULL, 0, &json_len) == WAYMARK_RESULT_PANIC && json_len == 12345,
          "export after the panic");
    CHECK(waymark_engine_zone_count(engine, &zones) == WAYMARK_RESULT_OK, "zone count (from the site)");
    CHECK(waymark_engine_zone_posterior(engine, posterior, 1) == WAYMARK_RESULT_PANIC && posterior[0] == -1.0,
          "zone posterior after the panic");
    CHECK(waymark_engine_fix_bias(engine, &fix) == WAYMARK_RESULT_PANIC && fix.spread == -1.0,
          "fix error after the panic");
    CHECK(waymark_engine_push_scan(engine, 3000000000ull, &known, 1, NULL, 0, NULL) == WAYMARK_RESULT_PANIC,
          "scan after the panic");
    CHECK(waymark_engine_set_status_callback(engine, NULL, NULL) == WAYMARK_RESULT_OK, "clear status callback");
    waymark_engine_free(engine);
    CHECK(waymark_set_log_callback(WAYMARK_LOG_LEVEL_WARN, NULL, NULL) == WAYMARK_RESULT_OK, "log hook off");
}

/* The survey recorder: a short walk on two floors written as walk files, bad input refused
 * with the right codes, the files' paths, and nothing written without a waypoint. */
static void survey_recorder(void) {
    char dir[] = "/tmp/waymark-recorder-XXXXXX";
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    waymark_recorder *rec = NULL;
    CHECK(waymark_recorder_new(dir, "bad/name", NULL, NULL, &rec) == WAYMARK_RESULT_INPUT_REJECTED && rec == NULL,
          "a walk name that is not a file name");
    CHECK(waymark_recorder_new(NULL, "walk", NULL, NULL, &rec) == WAYMARK_RESULT_NULL_PARAMETER, "NULL directory");
    CHECK(waymark_recorder_new(dir, "walk", "office", "Test Phone", &rec) == WAYMARK_RESULT_OK && rec, "new");
    waymark_sample accel[3] = {{1000, 0.1, 0.2, 9.8}, {2000, NAN, 0.0, 9.8}, {3000, 0.1, 0.2, 9.7}};
    size_t accepted = 0;
    CHECK(waymark_recorder_push_accelerometer(rec, accel, 3, &accepted) == WAYMARK_RESULT_OK && accepted == 2,
          "NaN dropped: %zu", accepted);
    waymark_wifi_reading ap = {"aa:bb:cc:dd:ee:01", -61.5, 250};
    waymark_beacon_reading beacon = {"fda50693-a4e2-4fb1-afcf-c6eb07647825", 7, 9, -80.0, 0, NULL};
    CHECK(waymark_recorder_push_scan(rec, 5000000000ull, &ap, 1, &beacon, 1) == WAYMARK_RESULT_OK, "scan");
    CHECK(waymark_recorder_push_scan(rec, 5000000000ull, &ap, 1, NULL, 0) == WAYMARK_RESULT_INPUT_REJECTED, "duplicate scan");
    CHECK(waymark_recorder_push_scan(rec, 5100000000ull, NULL, 0, NULL, 0) == WAYMARK_RESULT_INPUT_REJECTED, "empty scan");
    CHECK(waymark_recorder_mark_waypoint(rec, 6000000000ull, NAN, 1.0, "F1") == WAYMARK_RESULT_INPUT_REJECTED, "NaN waypoint");
    CHECK(waymark_recorder_mark_waypoint(rec, 6000000000ull, 1.0, 2.0, "../F1") == WAYMARK_RESULT_INPUT_REJECTED, "bad floor");
    CHECK(waymark_recorder_mark_waypoint(rec, 6000000000ull, 1.0, 2.0, "F1") == WAYMARK_RESULT_OK, "waypoint F1");
    CHECK(waymark_recorder_mark_waypoint(rec, 9000000000ull, 3.0, 2.0, "F2") == WAYMARK_RESULT_OK, "waypoint F2");
    waymark_recording_summary summary;
    CHECK(waymark_recorder_finish(rec, &summary) == WAYMARK_RESULT_OK, "finish");
    CHECK(summary.samples == 2 && summary.samples_dropped == 1 && summary.scans == 1 && summary.scans_rejected == 2 &&
              summary.waypoints == 2 && summary.files == 2,
          "summary %llu %llu %llu %llu %llu %llu", (unsigned long long)summary.samples,
          (unsigned long long)summary.samples_dropped, (unsigned long long)summary.scans,
          (unsigned long long)summary.scans_rejected, (unsigned long long)summary.waypoints,
          (unsigned long long)summary.files);
    CHECK(waymark_recorder_push_accelerometer(rec, accel, 1, NULL) == WAYMARK_RESULT_FINISHED, "after finish");
    size_t len = 0;
    char small[4];
    CHECK(waymark_recorder_file_path(rec, 0, small, sizeof small, &len) == WAYMARK_RESULT_BUFFER_TOO_SMALL &&
              small[0] == 0 && len > 4,
          "small buffer");
    char path[512];
    CHECK(waymark_recorder_file_path(rec, 0, path, sizeof path, &len) == WAYMARK_RESULT_OK && strlen(path) == len,
          "path");
    CHECK(strstr(path, "/F1/path_data_files/walk-1.txt") != NULL, "first file %s", path);
    CHECK(waymark_recorder_file_path(rec, 2, path, sizeof path, NULL) == WAYMARK_RESULT_INPUT_REJECTED, "no third file");
    CHECK(waymark_recorder_file_path(rec, 0, path, sizeof path, NULL) == WAYMARK_RESULT_OK, "path again");
    size_t n = 0;
    char *text = read_file(path, &n);
    CHECK(text != NULL, "read %s", path);
    if (text) {
        CHECK(strstr(text, "Recorder:waymark\tTimeUnit:ns") != NULL, "the recorder's header");
        CHECK(strstr(text, "3000\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.7\n") != NULL, "a sample line");
        CHECK(strstr(text, "5000000000\tTYPE_WIFI\t\taa:bb:cc:dd:ee:01\t-61.5\t0\t4750000000\n") != NULL,
              "a WiFi line, last seen 250 ms before its scan");
        CHECK(strstr(text, "5000000000\tTYPE_BEACON\tfda50693-a4e2-4fb1-afcf-c6eb07647825\t7\t9\t0\t-80\t0\t\t5000000000\n") != NULL,
              "a beacon line");
        CHECK(strstr(text, "6000000000\tTYPE_WAYPOINT\t1\t2\n") != NULL, "the waypoint");
        free(text);
    }
    waymark_recorder_free(rec);
    waymark_recorder_free(NULL);

    waymark_recorder *empty = NULL;
    CHECK(waymark_recorder_new(dir, "empty", NULL, NULL, &empty) == WAYMARK_RESULT_OK, "new");
    CHECK(waymark_recorder_push_gyroscope(empty, accel, 1, NULL) == WAYMARK_RESULT_OK, "gyro");
    CHECK(waymark_recorder_finish(empty, NULL) == WAYMARK_RESULT_NO_WAYPOINTS, "no waypoint, no file");
    waymark_recorder_free(empty);
}

/* Revisions of the track the status callback heard. */
static void on_revision(void *userdata, const waymark_status *status) {
    if (status->kind == WAYMARK_STATUS_KIND_TRACK_REVISED && status->point_count > 0) (*(int *)userdata)++;
}

/* Positions and the sum of their x + y + radius (to compare runs), from `summed`. */
typedef struct {
    int positions;
    double sum;
} summed_positions;

static void summed(waymark_engine *engine, unsigned long long t, double tx, double ty, const waymark_position *p,
                   void *context) {
    (void)engine;
    (void)t;
    (void)tx;
    (void)ty;
    summed_positions *s = context;
    s->positions++;
    s->sum += p->x + p->y + p->accuracy_m;
}

/* The walk replayed with `track` set as given: its positions, and the track revisions reported. */
static summed_positions replay_track(const char *site_path, const char *walk_path, uint8_t track, int *revisions) {
    summed_positions out = {0, 0.0};
    waymark_engine_options options;
    waymark_engine_options_default(&options);
    options.track = track;
    size_t len = 0;
    char *json = read_file(site_path, &len);
    waymark_engine *engine = NULL;
    CHECK(json && waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
                      WAYMARK_RESULT_OK,
          "engine with track = %u", track);
    free(json);
    if (!engine) return out;
    CHECK(waymark_engine_set_status_callback(engine, on_revision, revisions) == WAYMARK_RESULT_OK, "status");
    replay(engine, walk_path, summed, &out);
    waymark_engine_free(engine);
    return out;
}

/* `track` = 0 gives the same positions with no revision reported; only 0 and 1 are valid. */
static void without_track(const char *site_path, const char *walk_path) {
    waymark_engine_options options;
    CHECK(waymark_engine_options_default(&options) == WAYMARK_RESULT_OK && options.track == 1, "track by default");
    options.track = 2;
    size_t len = 0;
    char *json = read_file(site_path, &len);
    waymark_engine *engine = NULL;
    CHECK(json && waymark_engine_new_with_options((const uint8_t *)json, len, &options, &engine) ==
                      WAYMARK_RESULT_INVALID_CONFIG && engine == NULL,
          "track = 2");
    free(json);
    int with_revisions = 0, without_revisions = 0;
    summed_positions with = replay_track(site_path, walk_path, 1, &with_revisions);
    summed_positions without = replay_track(site_path, walk_path, 0, &without_revisions);
    printf("track kept: %d positions, %d revisions; without: %d positions, %d revisions\n", with.positions,
           with_revisions, without.positions, without_revisions);
    CHECK(with.positions > 10 && with.positions == without.positions && with.sum == without.sum,
          "the same positions without the track (%d, %d)", with.positions, without.positions);
    CHECK(with_revisions > 0 && without_revisions == 0, "revisions %d with the track, %d without", with_revisions,
          without_revisions);
}

int main(int argc, char **argv) {
    if (argc != 6) {
        fprintf(stderr, "usage: %s site.json walk.txt site-hashed.json salt.hex site.wmsite\n", argv[0]);
        return 2;
    }
    uint8_t salt[64];
    size_t salt_len = read_salt(argv[4], salt, sizeof salt);
    CHECK(salt_len >= 16, "salt file %s", argv[4]);
    error_paths(argv[1]);
    options_status_and_stats(argv[1]);
    address_beacons(argv[1]);
    geo_reference(argv[1]);
    lat_lon_layers(argv[1]);
    zones_and_feedback(argv[1]);
    geofences_and_zone_events(argv[1]);
    routes(argv[1]);
    survey_recorder();
    walk(argv[1], argv[2], NULL, 0);
    without_track(argv[1], argv[2]);
    habits(argv[1], argv[2]);
    walk(argv[5], argv[2], NULL, 0);
    binary_site(argv[5]);
    walk(argv[3], argv[2], salt, salt_len);
    salted(argv[3], salt, salt_len);
    session_evidence(argv[1], argv[2], argv[3], argv[5]);
    printf("%d passed, %d failed\n", checks - failures, failures);
    return failures ? 1 : 0;
}
