/* What the C tests share: a counting CHECK and reading a file whole. Included once per test
 * program (test.c, robustness.c). */
#ifndef WAYMARK_TEST_CHECK_H
#define WAYMARK_TEST_CHECK_H

#include <stdio.h>
#include <stdlib.h>

static int failures = 0, checks = 0;
#define CHECK(cond, ...)                                         \
    do {                                                         \
        checks++;                                                \
        if (!(cond)) {                                           \
            failures++;                                          \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__); \
            fprintf(stderr, __VA_ARGS__);                        \
            fprintf(stderr, "\n");                               \
        }                                                        \
    } while (0)

static char *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *buf = malloc((size_t)n + 1);
    if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    if (buf) buf[n] = 0;
    *len = (size_t)n;
    return buf;
}

/* The site file named by the only argument, read whole (exits 2 on a wrong argument count,
 * 1 if it cannot be read). */
static inline char *site_argument(int argc, char **argv, size_t *len) {
    if (argc != 2) {
        fprintf(stderr, "usage: %s site.json\n", argv[0]);
        exit(2);
    }
    char *json = read_file(argv[1], len);
    CHECK(json != NULL, "read %s", argv[1]);
    if (!json) exit(1);
    return json;
}

#endif
