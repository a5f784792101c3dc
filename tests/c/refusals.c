/* What an engine's mistakes get from the C library: each call below is refused with a status and
 * a message naming the argument, the process stays alive and nothing is printed on stderr. Then a
 * model loaded from memory runs bit-identically to the same file loaded from disk.
 *
 * Usage: refusals TRANSITION_MODEL.onnx
 * Prints one line per case: "<case> <status name> <message>", then "memory: identical". */
#include "zoo.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

static void refused(const char *what, ZooStatus status, ZooStatus want, const char *needle) {
    char message[1024];
    zoo_last_error(message, sizeof message);
    printf("%s %s %s\n", what, zoo_status_string((int32_t)status), message);
    if (status != want || strstr(message, needle) == NULL) {
        printf("FAIL %s: wanted %s and a message with `%s`\n", what, zoo_status_string((int32_t)want), needle);
        failures++;
    }
}

/* Runs a 4-character transition of `model` from a standing pose; the frames in `out`. */
static ZooStatus run(const ZooModel *model, float *out, size_t out_len) {
    ZooModelInfo info;
    ZooTransitionInfo t;
    ZooStatus s;
    if ((s = zoo_model_info(model, &info)) != ZOO_STATUS_OK) return s;
    if ((s = zoo_transition_info(model, &t)) != ZOO_STATUS_OK) return s;
    size_t n = 4, k = info.joints, d = 3 * k, past = t.past_frames, length = t.transition_frames;
    if ((length + 1) * n * d > out_len) return ZOO_STATUS_INVALID_ARGUMENT;
    ZooTransitionRunner *runner = NULL;
    ZooTransitionCharacters *chars = NULL;
    if ((s = zoo_transition_runner_new(model, n, &runner)) != ZOO_STATUS_OK) return s;
    if ((s = zoo_transition_characters_new(model, n, &chars)) != ZOO_STATUS_OK) return s;
    float *p = calloc(n * past * d, sizeof(float)), *target = calloc(n * d, sizeof(float)),
          *next = calloc(n * d, sizeof(float));
    for (size_t c = 0; c < n; c++)
        for (size_t f = 0; f < past; f++)
            for (size_t j = 0; j < k; j++) {
                float *v = &p[(c * past + f) * d + 3 * j];
                v[0] = (float)c * 10.0f + (float)j;
                v[1] = 90.0f - 10.0f * (float)j;
                v[2] = 3.0f * (float)f;
                target[c * d + 3 * j + 0] = v[0] + 5.0f;
                target[c * d + 3 * j + 1] = v[1];
                target[c * d + 3 * j + 2] = 3.0f * (float)(past + length);
                next[c * d + 3 * j + 0] = v[0] + 5.0f;
                next[c * d + 3 * j + 1] = v[1];
                next[c * d + 3 * j + 2] = 3.0f * (float)(past + length + 1);
            }
    s = zoo_transition_start(runner, chars, p, n * past * d, target, n * d, next, n * d, length);
    for (size_t f = 0; s == ZOO_STATUS_OK && f <= length; f++) s = zoo_transition_step(runner, chars, out + f * n * d, n * d);
    free(p);
    free(target);
    free(next);
    zoo_transition_characters_free(chars);
    zoo_transition_runner_free(runner);
    return s;
}

int main(int argc, char **argv) {
    if (argc != 2) {
        printf("usage: refusals TRANSITION_MODEL.onnx\n");
        return 2;
    }
    if (zoo_abi_version() != ZOO_ABI_VERSION) {
        printf("FAIL the library's ABI %u is not the header's %d\n", zoo_abi_version(), ZOO_ABI_VERSION);
        return 1;
    }
    printf("version %s\n", zoo_version_string());
    ZooModel *model = NULL;
    ZooStatus s = zoo_model_load(argv[1], &model);
    if (s != ZOO_STATUS_OK) {
        printf("FAIL cannot load %s\n", argv[1]);
        return 1;
    }
    char message[64];
    if (zoo_last_error(message, sizeof message) != 0) {
        printf("FAIL a successful call left a last error: %s\n", message);
        failures++;
    }

    ZooTransitionCharacters *chars = NULL;
    ZooTransitionRunner *runner = NULL;
    ZooKeyframesRunner *krunner = NULL;
    ZooSynthesisRunner *srunner = NULL;
    refused("characters_1<<40", zoo_transition_characters_new(model, (size_t)1 << 40, &chars),
            ZOO_STATUS_INVALID_ARGUMENT, "more than ZOO_MAX_BATCH (65536)");
    refused("characters_SIZE_MAX", zoo_transition_characters_new(model, SIZE_MAX, &chars),
            ZOO_STATUS_INVALID_ARGUMENT, "`count` is 18446744073709551615");
    refused("characters_minus_1", zoo_transition_characters_new(model, (size_t)-1, &chars),
            ZOO_STATUS_INVALID_ARGUMENT, "ZOO_MAX_BATCH");
    refused("characters_0", zoo_transition_characters_new(model, 0, &chars), ZOO_STATUS_INVALID_ARGUMENT,
            "`count` is 0");
    refused("runner_max_batch_1<<40", zoo_transition_runner_new(model, (size_t)1 << 40, &runner),
            ZOO_STATUS_INVALID_ARGUMENT, "`max_batch` is 1099511627776");
    /* The same counts for a model of another task: the task is checked first. */
    refused("keyframes_runner_on_a_transition_model", zoo_keyframes_runner_new(model, SIZE_MAX, &krunner),
            ZOO_STATUS_WRONG_MODEL, "zoo_transition_*");
    refused("synthesis_runner_on_a_transition_model", zoo_synthesis_runner_new(model, SIZE_MAX, &srunner),
            ZOO_STATUS_WRONG_MODEL, "zoo_transition_*");

    /* A buffer length no buffer can have (a negative length converted to size_t). */
    ZooModelInfo info;
    zoo_model_info(model, &info);
    ZooTransitionRunner *r = NULL;
    zoo_transition_runner_new(model, 1, &r);
    zoo_transition_characters_new(model, 1, &chars);
    float buffer[16] = {0};
    refused("step_len_minus_1", zoo_transition_step(r, chars, buffer, (size_t)-1), ZOO_STATUS_INVALID_ARGUMENT,
            "more than any buffer can hold");
    int32_t parents[64];
    refused("skeleton_len_SIZE_MAX", zoo_model_skeleton(model, parents, SIZE_MAX, NULL, 0),
            ZOO_STATUS_INVALID_ARGUMENT, "more than any buffer can hold");
    /* A batch larger than the runner was made for. */
    ZooTransitionCharacters *two = NULL;
    zoo_transition_characters_new(model, 2, &two);
    refused("batch_above_max_batch", zoo_transition_step(r, two, buffer, 16), ZOO_STATUS_INVALID_ARGUMENT,
            "more than the runner's `max_batch` (1)");
    zoo_transition_characters_free(two);
    zoo_transition_characters_free(chars);
    zoo_transition_runner_free(r);

    /* Enum values from outside their enums. */
    ZooCoordinateFrame unity = {1.0f, ZOO_UP_AXIS_Y, ZOO_HANDEDNESS_LEFT};
    ZooCoordinateFrame up7 = unity, hand9 = unity;
    up7.up_axis = 7;
    hand9.handedness = 9;
    float position[3] = {1.0f, 2.0f, 3.0f};
    refused("up_axis_7", zoo_positions_convert(&up7, &unity, position, 3), ZOO_STATUS_INVALID_ARGUMENT,
            "`from.up_axis` is 7, not a ZooUpAxis");
    refused("handedness_9", zoo_positions_convert(&unity, &hand9, position, 3), ZOO_STATUS_INVALID_ARGUMENT,
            "`to.handedness` is 9, not a ZooHandedness");
    refused("log_level_9", zoo_set_log_callback(NULL, NULL, 9), ZOO_STATUS_INVALID_ARGUMENT,
            "`max_level` is 9, not a ZooLogLevel");
    if (strcmp(zoo_status_string(12345), "ZOO_STATUS_UNKNOWN") != 0) {
        printf("FAIL zoo_status_string(12345)\n");
        failures++;
    }
    /* Loading from memory: an empty buffer, bytes that are not a model. */
    ZooModel *bad = NULL;
    refused("memory_empty", zoo_model_load_memory((const uint8_t *)"", 0, &bad), ZOO_STATUS_LOAD_FAILED,
            "`bytes_len` is 0");
    refused("memory_garbage", zoo_model_load_memory((const uint8_t *)"not a model", 11, &bad),
            ZOO_STATUS_LOAD_FAILED, "the model in memory");

    /* The model from memory runs bit-identically to the file. */
    FILE *f = fopen(argv[1], "rb");
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *bytes = malloc((size_t)size);
    if (fread(bytes, 1, (size_t)size, f) != (size_t)size) {
        printf("FAIL cannot read %s\n", argv[1]);
        return 1;
    }
    fclose(f);
    ZooModel *from_memory = NULL;
    if (zoo_model_load_memory(bytes, (size_t)size, &from_memory) != ZOO_STATUS_OK) {
        zoo_last_error(message, sizeof message);
        printf("FAIL zoo_model_load_memory: %s\n", message);
        return 1;
    }
    memset(bytes, 0xAB, (size_t)size); /* the library keeps no pointer to them */
    free(bytes);
    size_t len = 4 * 64 * 3 * (size_t)info.joints;
    float *a = calloc(len, sizeof(float)), *b = calloc(len, sizeof(float));
    if (run(model, a, len) != ZOO_STATUS_OK || run(from_memory, b, len) != ZOO_STATUS_OK) {
        printf("FAIL the transition did not run\n");
        return 1;
    }
    printf("memory: %s\n", memcmp(a, b, len * sizeof(float)) == 0 ? "identical" : "DIFFERENT");
    if (memcmp(a, b, len * sizeof(float)) != 0) failures++;
    free(a);
    free(b);
    zoo_model_free(from_memory);
    zoo_model_free(model);
    return failures == 0 ? 0 : 1;
}
