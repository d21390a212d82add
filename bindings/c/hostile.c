/* Hostile inputs (issue 60) through the C ABI: a recorder whose storage fails never reports
 * success for what it did not write and its error sticks until waymark_recorder_resume; what
 * comes before the first waypoint is on disk, not in memory; floor names that would share a
 * folder on case-insensitive storage are refused; and one sample or scan with a time far ahead
 * (a negative int64 passed as unsigned) is refused, counted and reported to the status
 * callback, and the stream goes on. test.sh runs it under valgrind. Usage: hostile site.json */
#define _DEFAULT_SOURCE /* mkdtemp */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "waymark.h"
#include "check.h"

static void write_empty_file(const char *path) {
    FILE *f = fopen(path, "w");
    CHECK(f != NULL, "create %s", path);
    if (f) fclose(f);
}

/* A folder that cannot be created (its parent is a file; root can write anywhere, so a
 * read-only folder would not do): every call after the first failed write returns IO. */
static void recorder_on_unusable_storage(const char *tmp) {
    char file[512], dir[600];
    snprintf(file, sizeof file, "%s/a-file", tmp);
    snprintf(dir, sizeof dir, "%s/walks", file);
    write_empty_file(file);
    waymark_recorder *rec = NULL;
    CHECK(waymark_recorder_new(dir, "walk", NULL, NULL, &rec) == WAYMARK_RESULT_OK && rec, "new");
    waymark_sample s[] = {{1000, 0, 0, 9.8}, {2000, 0, 0, 9.8}};
    size_t accepted = 99;
    CHECK(waymark_recorder_push_accelerometer(rec, s, 1, &accepted) == WAYMARK_RESULT_IO, "first push: IO");
    CHECK(waymark_recorder_push_accelerometer(rec, s + 1, 1, &accepted) == WAYMARK_RESULT_IO, "later push: IO too");
    CHECK(waymark_recorder_mark_waypoint(rec, 3000, 1, 2, "F1") == WAYMARK_RESULT_IO, "waypoint: IO");
    waymark_recording_summary summary;
    CHECK(waymark_recorder_finish(rec, &summary) == WAYMARK_RESULT_IO, "finish: IO, not NO_WAYPOINTS");
    CHECK(waymark_recorder_get_summary(rec, &summary) == WAYMARK_RESULT_OK && summary.samples == 0 &&
              summary.waypoints == 0 && summary.files == 0,
          "nothing counted");
    CHECK(waymark_recorder_resume(rec) == WAYMARK_RESULT_OK, "acknowledged");
    CHECK(waymark_recorder_push_accelerometer(rec, s, 1, NULL) == WAYMARK_RESULT_IO, "still unusable");
    CHECK(waymark_recorder_finish(rec, NULL) == WAYMARK_RESULT_IO, "finish can be retried");
    CHECK(waymark_recorder_resume(NULL) == WAYMARK_RESULT_NULL_PARAMETER, "NULL recorder");
    waymark_recorder_free(rec);
    unlink(file);
}

static void recorder_spool_and_floor_names(const char *tmp) {
    waymark_recorder *rec = NULL;
    CHECK(waymark_recorder_new(tmp, "walk", NULL, NULL, &rec) == WAYMARK_RESULT_OK && rec, "new");
    waymark_sample s[] = {{1000, 0, 0, 9.8}, {2000, 0, 0, 9.8}};
    CHECK(waymark_recorder_push_gyroscope(rec, s, 2, NULL) == WAYMARK_RESULT_OK, "before the first waypoint");
    char spool[600];
    snprintf(spool, sizeof spool, "%s/.walk.pending", tmp);
    size_t len = 0;
    char *text = read_file(spool, &len);
    CHECK(text && strstr(text, "2000\tTYPE_GYROSCOPE") != NULL, "on disk before the first waypoint");
    free(text);
    CHECK(waymark_recorder_finish(rec, NULL) == WAYMARK_RESULT_NO_WAYPOINTS, "no waypoint yet");
    CHECK(waymark_recorder_resume(rec) == WAYMARK_RESULT_OK, "resume without an error");
    CHECK(waymark_recorder_mark_waypoint(rec, 3000, 1, 2, "F1 ") == WAYMARK_RESULT_INPUT_REJECTED, "'F1 '");
    CHECK(waymark_recorder_mark_waypoint(rec, 3000, 1, 2, "F1.") == WAYMARK_RESULT_INPUT_REJECTED, "'F1.'");
    CHECK(waymark_recorder_mark_waypoint(rec, 3000, 1, 2, "F1") == WAYMARK_RESULT_OK, "F1");
    CHECK(waymark_recorder_mark_waypoint(rec, 4000, 1, 2, "f1") == WAYMARK_RESULT_INPUT_REJECTED,
          "'f1' beside 'F1'");
    CHECK(access(spool, F_OK) != 0, "the spool went into the walk file");
    waymark_sample ahead[] = {{UINT64_MAX - 999, 0, 0, 9.8}, {5000, 0, 0, 9.8}};
    size_t accepted = 0;
    CHECK(waymark_recorder_push_gyroscope(rec, ahead, 2, &accepted) == WAYMARK_RESULT_OK && accepted == 1,
          "a negative time refused, the stream goes on: %zu", accepted);
    waymark_recording_summary summary;
    CHECK(waymark_recorder_finish(rec, &summary) == WAYMARK_RESULT_OK && summary.samples == 3 &&
              summary.samples_dropped == 1 && summary.files == 1,
          "finish");
    char path[600];
    CHECK(waymark_recorder_file_path(rec, 0, path, sizeof path, NULL) == WAYMARK_RESULT_OK, "path");
    text = read_file(path, &len);
    CHECK(text && len > 0 && text[len - 1] == '\n' && strstr(text, "5000\tTYPE_GYROSCOPE") != NULL, "whole lines");
    free(text);
    unlink(path);
    waymark_recorder_free(rec);
}

typedef struct {
    int rejected;
} heard;

static void on_status(void *userdata, const waymark_status *status) {
    if (status->kind == WAYMARK_STATUS_KIND_ERROR && status->error == WAYMARK_RESULT_INPUT_REJECTED)
        ((heard *)userdata)->rejected++;
}

/* One accelerometer sample at a negative time passed as unsigned used to become the stream's
 * clock: every later sample was out of order, silently. */
static void time_far_ahead(waymark_engine *engine) {
    heard h = {0};
    CHECK(waymark_engine_set_status_callback(engine, on_status, &h) == WAYMARK_RESULT_OK, "status callback");
    waymark_sample first[100];
    for (int k = 0; k < 100; k++) first[k] = (waymark_sample){(uint64_t)(k + 1) * 10000000ull, 0, 0, 9.81};
    size_t accepted = 0;
    CHECK(waymark_engine_push_accelerometer(engine, first, 100, &accepted) == WAYMARK_RESULT_OK && accepted == 100,
          "on time");
    waymark_sample negative = {(uint64_t)-1000000, 0, 0, 9.81};
    CHECK(waymark_engine_push_accelerometer(engine, &negative, 1, &accepted) == WAYMARK_RESULT_OK && accepted == 0,
          "refused");
    CHECK(h.rejected == 1, "the status callback heard it: %d", h.rejected);
    waymark_sample later[100];
    for (int k = 0; k < 100; k++) later[k] = (waymark_sample){(uint64_t)(k + 101) * 10000000ull, 0, 0, 9.81};
    CHECK(waymark_engine_push_accelerometer(engine, later, 100, &accepted) == WAYMARK_RESULT_OK && accepted == 100,
          "the stream goes on: %zu taken", accepted);
    waymark_wifi_reading known = {"02:00:00:00:00:00", -60.0, 0};
    CHECK(waymark_engine_push_scan(engine, UINT64_MAX - 8, &known, 1, NULL, 0, NULL) ==
              WAYMARK_RESULT_INPUT_REJECTED,
          "a scan past any clock");
    CHECK(h.rejected == 2, "heard: %d", h.rejected);
    waymark_position p;
    CHECK(waymark_engine_push_scan(engine, 2000000000ull, &known, 1, NULL, 0, &p) == WAYMARK_RESULT_OK,
          "later epochs are taken");
    waymark_input_stats stats;
    CHECK(waymark_engine_input_stats(engine, &stats) == WAYMARK_RESULT_OK && stats.timestamps_ahead == 2 &&
              stats.scans_accepted == 1,
          "counted: %llu", (unsigned long long)stats.timestamps_ahead);
    CHECK(waymark_engine_set_status_callback(engine, NULL, NULL) == WAYMARK_RESULT_OK, "status callback off");
}

int main(int argc, char **argv) {
    size_t len = 0;
    char *json = site_argument(argc, argv, &len);
    char tmp[] = "/tmp/waymark-hostile-XXXXXX";
    CHECK(mkdtemp(tmp) != NULL, "mkdtemp");
    recorder_on_unusable_storage(tmp);
    recorder_spool_and_floor_names(tmp);
    char folder[600];
    snprintf(folder, sizeof folder, "%s/F1/path_data_files", tmp);
    rmdir(folder);
    snprintf(folder, sizeof folder, "%s/F1", tmp);
    rmdir(folder);
    CHECK(rmdir(tmp) == 0, "every file cleaned up");

    waymark_engine *engine = NULL;
    CHECK(waymark_engine_new((const uint8_t *)json, len, &engine) == WAYMARK_RESULT_OK, "site");
    free(json);
    if (!engine) return 1;
    time_far_ahead(engine);
    waymark_engine_free(engine);
    printf("%d passed, %d failed\n", checks - failures, failures);
    return failures ? 1 : 0;
}
