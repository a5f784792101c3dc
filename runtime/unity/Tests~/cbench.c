/* The C side of the Unity package's timing (tests/unity.rs builds it as libzoo_cbench.so and the
 * console test calls it through P/Invoke, so that both sides run in one process, transition
 * after transition): the per-frame loop of an engine written in C over the same C ABI the C#
 * wrappers call, on the same model file and inputs. */
#define _POSIX_C_SOURCE 199309L
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "zoo.h"

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* An engine's transition loop: model, runner, characters, a copy of the inputs, output buffers. */
typedef struct ZooCbench {
  ZooModel *model;
  ZooTransitionRunner *runner;
  ZooTransitionCharacters *chars;
  ZooCoordinateFrame frame, engine;
  int convert;
  size_t batch, joints, length, past_len, past_rotations_len, rotations_len;
  ZooRootMotion *past, *target, *next, *roots;
  float *past_rotations, *target_rotations, *next_rotations, *rotations;
} ZooCbench;

static void *copy(const void *from, size_t bytes) {
  void *to = malloc(bytes ? bytes : 1);
  if (to != NULL && bytes) memcpy(to, from, bytes);
  return to;
}

void zoo_cbench_free(ZooCbench *b) {
  if (b == NULL) return;
  zoo_transition_characters_free(b->chars);
  zoo_transition_runner_free(b->runner);
  zoo_model_free(b->model);
  free(b->past);
  free(b->target);
  free(b->next);
  free(b->roots);
  free(b->past_rotations);
  free(b->target_rotations);
  free(b->next_rotations);
  free(b->rotations);
  free(b);
}

/* Loads `path`, makes a runner for `batch` characters and `batch` characters and copies the inputs of a posed
 * transition of `length` frames (`past_*`: the context of every character, `target_*` / `next_*`:
 * one pose per character, `rotations_len` floats each). With `engine` NULL the poses are in the
 * model's frame; else they are in `engine`'s, converted to the model's once here and every stepped
 * frame back to `engine`'s with `zoo_pose_convert` (what the C# wrapper does for an engine frame).
 * NULL on failure (zoo_last_error says why). */
ZooCbench *zoo_cbench_new(const char *path, size_t batch, const ZooRootMotion *past_roots, size_t past_roots_len,
                          const float *past_rotations, size_t past_rotations_len, const ZooRootMotion *target_roots,
                          const float *target_rotations, const ZooRootMotion *next_roots, const float *next_rotations,
                          size_t rotations_len, size_t length, const ZooCoordinateFrame *engine) {
  ZooModelInfo info;
  ZooCbench *b = (ZooCbench *)calloc(1, sizeof(ZooCbench));
  if (b == NULL) return NULL;
  if (zoo_model_load(path, &b->model) != ZOO_STATUS_OK || zoo_model_info(b->model, &info) != ZOO_STATUS_OK ||
      zoo_transition_runner_new(b->model, batch, &b->runner) != ZOO_STATUS_OK ||
      zoo_transition_characters_new(b->model, batch, &b->chars) != ZOO_STATUS_OK) {
    zoo_cbench_free(b);
    return NULL;
  }
  b->frame.metres_per_unit = info.metres_per_unit;
  b->frame.up_axis = (uint32_t)info.up_axis;
  b->frame.handedness = (uint32_t)info.handedness;
  b->convert = engine != NULL;
  if (engine != NULL) b->engine = *engine;
  b->batch = batch;
  b->joints = info.joints;
  b->length = length;
  b->past_len = past_roots_len;
  b->past_rotations_len = past_rotations_len;
  b->rotations_len = rotations_len;
  b->past = (ZooRootMotion *)copy(past_roots, past_roots_len * sizeof(ZooRootMotion));
  b->target = (ZooRootMotion *)copy(target_roots, batch * sizeof(ZooRootMotion));
  b->next = (ZooRootMotion *)copy(next_roots, batch * sizeof(ZooRootMotion));
  b->past_rotations = (float *)copy(past_rotations, past_rotations_len * sizeof(float));
  b->target_rotations = (float *)copy(target_rotations, rotations_len * sizeof(float));
  b->next_rotations = (float *)copy(next_rotations, rotations_len * sizeof(float));
  b->roots = (ZooRootMotion *)calloc(batch, sizeof(ZooRootMotion));
  b->rotations = (float *)calloc(batch * 4 * info.joints, sizeof(float));
  if (engine != NULL &&
      (zoo_pose_convert(engine, &b->frame, b->past, past_roots_len, b->past_rotations, past_rotations_len) != ZOO_STATUS_OK ||
       zoo_pose_convert(engine, &b->frame, b->target, batch, b->target_rotations, rotations_len) != ZOO_STATUS_OK ||
       zoo_pose_convert(engine, &b->frame, b->next, batch, b->next_rotations, rotations_len) != ZOO_STATUS_OK)) {
    zoo_cbench_free(b);
    return NULL;
  }
  return b;
}

/* Plays one transition: starts it (not timed) and steps it to its target frame. Returns the
 * seconds spent in the per-frame calls (`zoo_transition_step_posed`, and `zoo_pose_convert` when
 * converting), or -(1 + status) when a call fails. */
double zoo_cbench_transition(ZooCbench *b) {
  double start, spent;
  size_t s, n = b->batch, k = b->joints;
  ZooStatus status = zoo_transition_start_posed(b->runner, b->chars, b->past, b->past_len, b->past_rotations,
                                                b->past_rotations_len, b->target, n, b->target_rotations,
                                                b->rotations_len, b->next, n, b->next_rotations, b->rotations_len,
                                                b->length);
  start = now();
  for (s = 0; s <= b->length && status == ZOO_STATUS_OK; s++) {
    status = zoo_transition_step_posed(b->runner, b->chars, b->roots, n, b->rotations, n * 4 * k);
    if (status == ZOO_STATUS_OK && b->convert)
      status = zoo_pose_convert(&b->frame, &b->engine, b->roots, n, b->rotations, n * 4 * k);
  }
  spent = now() - start;
  return status == ZOO_STATUS_OK ? spent : -(1.0 + (double)status);
}
