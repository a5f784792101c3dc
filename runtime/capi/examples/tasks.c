/* The zoo C ABI's tasks besides transitions (examples/transition.c) in one engine-side program:
 * every model file given is loaded with zoo_model_load and run by its task (zoo_model_task):
 * complete an animator's keys with a keyframes model (ARNN), stitch a walk with a stitch model
 * (RMR: the whole sequence at once, then as a stream), synthesise motion for a batch of
 * characters with a synthesis model (RNN-GMM) and steer them with its controller.
 *
 * Build (from the repository root, after `cargo build -p zoo-capi`), as C99 or as C++17:
 *   cc -std=c99 -Wall -Wextra -Werror -Iruntime/capi/include runtime/capi/examples/tasks.c \
 *      target/debug/libzoo_capi.a -lm -lpthread -ldl -o tasks
 *   c++ -std=c++17 -x c++ -Wall -Wextra -Werror -Iruntime/capi/include runtime/capi/examples/tasks.c \
 *      -x none target/debug/libzoo_capi.a -lm -lpthread -ldl -o tasks
 * Run: ./tasks CHARACTERS FRAMES MODEL.onnx... (e.g. arnn.onnx rmr.onnx rnngmm.onnx)
 *
 * Prints one line per frame (and character), tagged by task:
 *   keys C T: character C's completed frame T (D values);
 *   stitch T / stream T: the refined pose of frame T of the whole sequence / of the stream: root
 *     position (3), root rotation (4), root delta (3), delta yaw, hips position (3), 4 values
 *     per joint (local rotations, x y z w), then 4 contacts (heel L, toe L, heel R, toe R);
 *   synth T C / control T C: character C's frame T, the same pose values, then 2 contacts
 *     (left, right).
 * tests/capi_tasks.rs runs it and compares every number with the Rust API.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include "zoo.h"

/* malloc of `count` values of `type`, cast for C++. */
#define NEW(type, count) ((type *)malloc((count) * sizeof(type)))

static int fail(const char *what, ZooStatus status) {
    char message[512];
    zoo_last_error(message, sizeof message);
    fprintf(stderr, "%s failed (status %d): %s\n", what, (int)status, message);
    return 1;
}

#define CHECK(call)                                  \
    do {                                             \
        ZooStatus s_ = (call);                       \
        if (s_ != ZOO_STATUS_OK) return fail(#call, s_); \
    } while (0)

static void print_pose(const ZooRootMotion *r, const float *rotations, size_t joints) {
    for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->root_position[i]);
    for (int i = 0; i < 4; i++) printf(" %.9g", (double)r->root_rotation[i]);
    for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->delta_position[i]);
    printf(" %.9g", (double)r->delta_yaw);
    for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->hips_position[i]);
    for (size_t i = 0; i < 4 * joints; i++) printf(" %.9g", (double)rotations[i]);
}

static void print_contacts(const uint8_t *contacts, size_t n) {
    for (size_t i = 0; i < n; i++) printf(" %d", (int)contacts[i]);
    printf("\n");
}

/* Key k (at frame `frame`) of character c, value j. The Rust side builds the same keys. */
static float key_value(size_t c, size_t k, size_t j, size_t frame) {
    return (float)(0.3 * sin(0.7 * (double)k + 1.3 * (double)j + 0.5 * (double)c) + 0.01 * (double)frame);
}

static int keyframes(const ZooModel *model) {
    ZooKeyframesInfo info;
    CHECK(zoo_keyframes_info(model, &info));
    size_t d = info.frame_values;
    /* Character 0: keys at 0, 9, 24, 39; character 1: at 0, 12, 30. */
    const size_t counts[2] = {4, 3};
    const size_t frames[7] = {0, 9, 24, 39, 0, 12, 30};
    float *poses = NEW(float, 7 * d);
    for (size_t c = 0, at = 0; c < 2; c++)
        for (size_t k = 0; k < counts[c]; k++, at++)
            for (size_t j = 0; j < d; j++) poses[at * d + j] = key_value(c, k, j, frames[at]);
    size_t lengths[2] = {40, 31};
    float *out = NEW(float, (lengths[0] + lengths[1]) * d);
    ZooKeyframesRunner *runner = NULL;
    CHECK(zoo_keyframes_runner_new(model, 2, &runner));
    CHECK(zoo_keyframes_complete_batch(runner, counts, 2, frames, 7, poses, 7 * d, NULL, 0, out,
                                       (lengths[0] + lengths[1]) * d));
    for (size_t c = 0, at = 0; c < 2; c++)
        for (size_t t = 0; t < lengths[c]; t++, at++) {
            printf("keys %zu %zu", c, t);
            for (size_t j = 0; j < d; j++) printf(" %.9g", (double)out[at * d + j]);
            printf("\n");
        }
    zoo_keyframes_runner_free(runner);
    free(poses);
    free(out);
    return 0;
}

/* The hips height of a skeleton's rest pose: minus its lowest joint. */
static double hips_height(const int32_t *parents, const float *offsets, size_t joints) {
    double *rest_y = NEW(double, joints);
    double lowest = 0.0;
    for (size_t j = 0; j < joints; j++) {
        rest_y[j] = parents[j] < 0 ? 0.0 : rest_y[parents[j]] + offsets[3 * j + 1];
        if (rest_y[j] < lowest) lowest = rest_y[j];
    }
    free(rest_y);
    return -lowest;
}

/* Frame f of the walk to stitch: the root walks along +Z turning slowly, the joints sway. */
static void walk_pose(size_t joints, double height, double speed, size_t f, ZooRootMotion *root,
                      float *rotations) {
    double yaw = 0.01 * (double)f;
    root->root_position[0] = (float)(10.0 * sin(0.05 * (double)f));
    root->root_position[1] = 0.0f;
    root->root_position[2] = (float)(speed * (double)f);
    root->root_rotation[0] = 0.0f;
    root->root_rotation[1] = (float)sin(0.5 * yaw);
    root->root_rotation[2] = 0.0f;
    root->root_rotation[3] = (float)cos(0.5 * yaw);
    root->hips_position[0] = 0.0f;
    root->hips_position[1] = (float)height;
    root->hips_position[2] = 0.0f;
    for (size_t j = 0; j < joints; j++) {
        double angle = 0.3 * sin(0.2 * (double)f + (double)j);
        rotations[4 * j + 0] = (float)sin(0.5 * angle);
        rotations[4 * j + 1] = 0.0f;
        rotations[4 * j + 2] = 0.0f;
        rotations[4 * j + 3] = (float)cos(0.5 * angle);
    }
}

static int stitch(const ZooModel *model) {
    ZooModelInfo model_info;
    ZooStitchInfo info;
    CHECK(zoo_model_info(model, &model_info));
    CHECK(zoo_stitch_info(model, &info));
    size_t k = model_info.joints;
    int32_t *parents = NEW(int32_t, k);
    float *offsets = NEW(float, 3 * k);
    CHECK(zoo_model_skeleton(model, parents, k, offsets, 3 * k));
    double height = hips_height(parents, offsets, k), speed = 120.0 / (double)model_info.fps;
    /* Windows at 0, s, 2s and one ending on the last frame. */
    size_t frames = info.window + 2 * info.stride + 5;
    ZooRootMotion *roots = NEW(ZooRootMotion, frames);
    float *rotations = NEW(float, frames * 4 * k);
    for (size_t f = 0; f < frames; f++) walk_pose(k, height, speed, f, &roots[f], &rotations[f * 4 * k]);

    ZooRootMotion *out_roots = NEW(ZooRootMotion, frames);
    float *out_rotations = NEW(float, frames * 4 * k);
    uint8_t *contacts = NEW(uint8_t, frames * 4);
    CHECK(zoo_stitch_refine(model, roots, frames, rotations, frames * 4 * k, true, true, out_roots,
                            frames, out_rotations, frames * 4 * k, contacts, frames * 4));
    for (size_t f = 0; f < frames; f++) {
        printf("stitch %zu", f);
        print_pose(&out_roots[f], &out_rotations[f * 4 * k], k);
        print_contacts(&contacts[f * 4], 4);
    }

    /* The stream: push a frame, pop whatever is ready (latency frames later), finish. */
    ZooStitchStream *stream = NULL;
    CHECK(zoo_stitch_stream_new(model, &stream));
    size_t popped = 0;
    for (size_t f = 0; f <= frames; f++) {
        if (f < frames)
            CHECK(zoo_stitch_stream_push(stream, &roots[f], &rotations[f * 4 * k], 4 * k));
        else
            CHECK(zoo_stitch_stream_finish(stream));
        bool ready = false;
        CHECK(zoo_stitch_stream_ready(stream, &ready));
        while (ready) {
            ZooRootMotion root;
            CHECK(zoo_stitch_stream_pop(stream, &root, out_rotations, 4 * k, contacts, 4));
            printf("stream %zu", popped++);
            print_pose(&root, out_rotations, k);
            print_contacts(contacts, 4);
            CHECK(zoo_stitch_stream_ready(stream, &ready));
        }
    }
    fprintf(stderr, "stitched %zu frames; the stream's latency is %zu frames\n", frames, info.latency);
    zoo_stitch_stream_free(stream);
    free(parents);
    free(offsets);
    free(roots);
    free(rotations);
    free(out_roots);
    free(out_rotations);
    free(contacts);
    return 0;
}

static int synthesis(const ZooModel *model, size_t n, size_t total) {
    ZooModelInfo model_info;
    ZooSynthesisInfo info;
    CHECK(zoo_model_info(model, &model_info));
    CHECK(zoo_synthesis_info(model, &info));
    size_t k = model_info.joints, d = info.frame_values;
    /* Every character starts from the data's mean frame, side by side, seeds 100, 101, ... */
    uint64_t *seeds = NEW(uint64_t, n);
    float *frames = NEW(float, n * d);
    float *placements = NEW(float, n * 3);
    for (size_t c = 0; c < n; c++) {
        seeds[c] = 100 + c;
        CHECK(zoo_synthesis_mean_frame(model, &frames[c * d], d));
        placements[3 * c + 0] = (float)(200.0 * (double)c);
        placements[3 * c + 1] = 0.0f;
        placements[3 * c + 2] = (float)(0.1 * (double)c);
    }
    ZooRootMotion *roots = NEW(ZooRootMotion, n);
    float *rotations = NEW(float, n * 4 * k);
    uint8_t *contacts = NEW(uint8_t, n * 2);

    ZooSynthesisRunner *runner = NULL;
    ZooSynthesisCharacters *characters = NULL;
    CHECK(zoo_synthesis_runner_new(model, n, &runner));
    CHECK(zoo_synthesis_characters_new(model, seeds, n, &characters));
    CHECK(zoo_synthesis_start(characters, frames, n * d, placements, n * 3));
    for (size_t t = 0; t < total; t++) {
        CHECK(zoo_synthesis_step(runner, characters, 1.0f, roots, n, rotations, n * 4 * k, contacts, n * 2));
        for (size_t c = 0; c < n; c++) {
            printf("synth %zu %zu", t, c);
            print_pose(&roots[c], &rotations[c * 4 * k], k);
            print_contacts(&contacts[2 * c], 2);
        }
    }

    /* The controller: run at 150 units/s ahead, then turn to face +X. */
    ZooControlSettings settings;
    CHECK(zoo_control_settings_default(&settings));
    ZooControlRunner *control_runner = NULL;
    ZooControlCharacters *controlled = NULL;
    CHECK(zoo_control_runner_new(model, n, &control_runner));
    CHECK(zoo_control_characters_new(model, seeds, n, &settings, &controlled));
    CHECK(zoo_control_start(controlled, frames, n * d, placements, n * 3));
    ZooControl *controls = NEW(ZooControl, n);
    size_t control_frames = total < 60 ? total : 60;
    for (size_t t = 0; t < control_frames; t++) {
        for (size_t c = 0; c < n; c++) {
            controls[c].speed = 150.0f;
            controls[c].heading = t < control_frames / 2 ? 0.0f : 1.5707964f;
        }
        CHECK(zoo_control_step(control_runner, controlled, controls, n, roots, n, rotations, n * 4 * k,
                               contacts, n * 2));
        for (size_t c = 0; c < n; c++) {
            printf("control %zu %zu", t, c);
            print_pose(&roots[c], &rotations[c * 4 * k], k);
            print_contacts(&contacts[2 * c], 2);
        }
    }
    fprintf(stderr, "synthesised %zu frames and steered %zu for %zu characters\n", total, control_frames, n);

    zoo_control_characters_free(controlled);
    zoo_control_runner_free(control_runner);
    zoo_synthesis_characters_free(characters);
    zoo_synthesis_runner_free(runner);
    free(seeds);
    free(frames);
    free(placements);
    free(roots);
    free(rotations);
    free(contacts);
    free(controls);
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: %s CHARACTERS FRAMES MODEL.onnx...\n", argv[0]);
        return 2;
    }
    if (zoo_abi_version() != ZOO_ABI_VERSION) {
        fprintf(stderr, "the zoo library has C ABI version %u, this program was built for %d\n",
                (unsigned)zoo_abi_version(), ZOO_ABI_VERSION);
        return 1;
    }
    size_t n = (size_t)strtoul(argv[1], NULL, 10);
    size_t total = (size_t)strtoul(argv[2], NULL, 10);
    for (int i = 3; i < argc; i++) {
        /* One loader for every task; the task says which functions run the model. */
        ZooModel *model = NULL;
        CHECK(zoo_model_load(argv[i], &model));
        int failed = 0;
        switch (zoo_model_task(model)) {
        case ZOO_TASK_KEYFRAMES:
            failed = keyframes(model);
            break;
        case ZOO_TASK_STITCH:
            failed = stitch(model);
            break;
        case ZOO_TASK_SYNTHESIS:
            failed = synthesis(model, n, total);
            break;
        case ZOO_TASK_TRANSITION:
            fprintf(stderr, "%s is a transition model: run it with examples/transition.c\n", argv[i]);
            break;
        case ZOO_TASK_NONE:
            failed = 1;
            break;
        }
        zoo_model_free(model);
        if (failed) return 1;
    }
    return 0;
}
