/* An engine loop through the zoo C ABI: load an exported transition model, walk a batch of
 * characters forward and, every transition length, start a transition to a pose further ahead,
 * then step it one frame per tick as engine poses (root motion + local joint rotations).
 *
 * Build (from the repository root, after `cargo build -p zoo-capi`), as C99 or as C++17:
 *   cc -std=c99 -Wall -Wextra -Werror -Iruntime/capi/include runtime/capi/examples/transition.c \
 *      target/debug/libzoo_capi.a -lm -lpthread -ldl -o transition
 *   c++ -std=c++17 -x c++ -Wall -Wextra -Werror -Iruntime/capi/include runtime/capi/examples/transition.c \
 *      -x none target/debug/libzoo_capi.a -lm -lpthread -ldl -o transition
 * Run: ./transition rtn.onnx [CHARACTERS] [FRAMES]
 *
 * Prints one line per character and frame: frame, character, root position (3), root rotation
 * (4), root delta (3), delta yaw, hips position (3), then 4 values per joint (local rotations,
 * x y z w). tests/capi.rs runs it and compares every number with the Rust API.
 */
#include <math.h>
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

/* The input pose of character c at walk frame f: the root walks along +Z (speed units per
 * frame), the joints sway about X. The Rust side of tests/capi.rs builds the same poses. */
static void walk_pose(size_t joints, double hips_height, double speed, size_t c, size_t f,
                      ZooRootMotion *root, float *rotations) {
    root->root_position[0] = (float)(200.0 * (double)c);
    root->root_position[1] = 0.0f;
    root->root_position[2] = (float)(speed * (double)f);
    root->root_rotation[0] = 0.0f;
    root->root_rotation[1] = 0.0f;
    root->root_rotation[2] = 0.0f;
    root->root_rotation[3] = 1.0f;
    root->hips_position[0] = 0.0f;
    root->hips_position[1] = (float)hips_height;
    root->hips_position[2] = 0.0f;
    for (size_t j = 0; j < joints; j++) {
        double angle = 0.2 * sin(0.3 * (double)f + (double)j + 0.5 * (double)c);
        rotations[4 * j + 0] = (float)sin(0.5 * angle);
        rotations[4 * j + 1] = 0.0f;
        rotations[4 * j + 2] = 0.0f;
        rotations[4 * j + 3] = (float)cos(0.5 * angle);
    }
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s MODEL.onnx [CHARACTERS] [FRAMES]\n", argv[0]);
        return 2;
    }
    size_t n = argc > 2 ? (size_t)strtoul(argv[2], NULL, 10) : 3;
    size_t total = argc > 3 ? (size_t)strtoul(argv[3], NULL, 10) : 300;

    if (zoo_abi_version() != ZOO_ABI_VERSION) {
        fprintf(stderr, "the zoo library has C ABI version %u, this program was built for %d\n",
                (unsigned)zoo_abi_version(), ZOO_ABI_VERSION);
        return 1;
    }
    ZooModel *model = NULL;
    ZooStatus s = zoo_model_load(argv[1], &model);
    if (s != ZOO_STATUS_OK) return fail("zoo_model_load", s);
    if (zoo_model_task(model) != ZOO_TASK_TRANSITION) {
        fprintf(stderr, "%s is not a transition model (task %d)\n", argv[1], (int)zoo_model_task(model));
        zoo_model_free(model);
        return 1;
    }
    ZooModelInfo model_info;
    ZooTransitionInfo info;
    if ((s = zoo_model_info(model, &model_info)) != ZOO_STATUS_OK) return fail("zoo_model_info", s);
    if ((s = zoo_transition_info(model, &info)) != ZOO_STATUS_OK) return fail("zoo_transition_info", s);
    size_t k = model_info.joints;
    fprintf(stderr, "%zu joints, %zu context frames, transitions of %zu frames at %g fps, %g m per unit\n", k,
            info.past_frames, info.transition_frames, (double)model_info.fps, (double)model_info.metres_per_unit);

    /* The hips height of the rest pose: minus the lowest joint of the skeleton's rest pose. */
    int32_t *parents = NEW(int32_t, k);
    float *offsets = NEW(float, 3 * k);
    double *rest_y = NEW(double, k);
    if ((s = zoo_model_skeleton(model, parents, k, offsets, 3 * k)) != ZOO_STATUS_OK)
        return fail("zoo_model_skeleton", s);
    double lowest = 0.0;
    for (size_t j = 0; j < k; j++) {
        rest_y[j] = parents[j] < 0 ? 0.0 : rest_y[parents[j]] + offsets[3 * j + 1];
        if (rest_y[j] < lowest) lowest = rest_y[j];
    }
    double hips_height = -lowest;
    double speed = 120.0 / (double)model_info.fps;

    ZooTransitionRunner *runner = NULL;
    ZooTransitionCharacters *characters = NULL;
    if ((s = zoo_transition_runner_new(model, n, &runner)) != ZOO_STATUS_OK)
        return fail("zoo_transition_runner_new", s);
    if ((s = zoo_transition_characters_new(model, n, &characters)) != ZOO_STATUS_OK)
        return fail("zoo_transition_characters_new", s);

    size_t past_frames = info.past_frames, length = info.transition_frames;
    ZooRootMotion *past_roots = NEW(ZooRootMotion, n * past_frames);
    float *past_rotations = NEW(float, n * past_frames * 4 * k);
    ZooRootMotion *target_roots = NEW(ZooRootMotion, n);
    ZooRootMotion *next_roots = NEW(ZooRootMotion, n);
    float *target_rotations = NEW(float, n * 4 * k);
    float *next_rotations = NEW(float, n * 4 * k);
    ZooRootMotion *roots = NEW(ZooRootMotion, n);
    float *rotations = NEW(float, n * 4 * k);

    for (size_t tick = 0; tick < total; tick++) {
        if (tick % (length + 1) == 0) {
            /* Start every character's transition: the last context frames walked, a target
             * one transition ahead. */
            for (size_t c = 0; c < n; c++) {
                for (size_t f = 0; f < past_frames; f++) {
                    size_t i = c * past_frames + f;
                    walk_pose(k, hips_height, speed, c, tick + f, &past_roots[i], &past_rotations[i * 4 * k]);
                }
                size_t t = tick + past_frames + length;
                walk_pose(k, hips_height, speed, c, t, &target_roots[c], &target_rotations[c * 4 * k]);
                walk_pose(k, hips_height, speed, c, t + 1, &next_roots[c], &next_rotations[c * 4 * k]);
            }
            s = zoo_transition_start_posed(runner, characters, past_roots, n * past_frames, past_rotations,
                                           n * past_frames * 4 * k, target_roots, n, target_rotations, n * 4 * k,
                                           next_roots, n, next_rotations, n * 4 * k, length);
            if (s != ZOO_STATUS_OK) return fail("zoo_transition_start_posed", s);
        }
        s = zoo_transition_step_posed(runner, characters, roots, n, rotations, n * 4 * k);
        if (s != ZOO_STATUS_OK) return fail("zoo_transition_step_posed", s);
        for (size_t c = 0; c < n; c++) {
            const ZooRootMotion *r = &roots[c];
            printf("%zu %zu", tick, c);
            for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->root_position[i]);
            for (int i = 0; i < 4; i++) printf(" %.9g", (double)r->root_rotation[i]);
            for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->delta_position[i]);
            printf(" %.9g", (double)r->delta_yaw);
            for (int i = 0; i < 3; i++) printf(" %.9g", (double)r->hips_position[i]);
            for (size_t i = 0; i < 4 * k; i++) printf(" %.9g", (double)rotations[c * 4 * k + i]);
            printf("\n");
        }
    }
    float mean = 0.0f, max = 0.0f;
    if ((s = zoo_transition_target_miss(characters, 0, &mean, &max)) == ZOO_STATUS_OK)
        fprintf(stderr, "character 0: the network's last target frame missed by %.3f (mean) / %.3f (max)\n",
                (double)mean, (double)max);

    zoo_transition_characters_free(characters);
    zoo_transition_runner_free(runner);
    zoo_model_free(model);
    free(parents);
    free(offsets);
    free(rest_y);
    free(past_roots);
    free(past_rotations);
    free(target_roots);
    free(next_roots);
    free(target_rotations);
    free(next_rotations);
    free(roots);
    free(rotations);
    return 0;
}
