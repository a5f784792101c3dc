// Generated from runtime/capi/include/zoo.h by runtime/unity/Tools~/update-bindings.sh: do not edit;
// regenerate when the C ABI changes (Documentation~/zoo.md, "Updating the bindings").
using System;
using System.Runtime.InteropServices;

namespace Zoo.Native
{
    /// <summary>The functions of the C ABI (zoo.h, C ABI version 3), one P/Invoke each, with the C names and types.</summary>
    public static unsafe partial class ZooNative
    {
        /// <summary>The C ABI version these bindings were generated from (<c>ZOO_ABI_VERSION</c> of zoo.h).</summary>
        public const uint ZOO_ABI_VERSION = 3;

        /// <summary>
        /// The most characters one handle holds or one call runs (<c>count</c>, <c>max_batch</c>): a larger count
        /// is refused before anything is allocated. Make several handles for a larger crowd.
        /// </summary>
        public const int ZOO_MAX_BATCH = 65536;

        /// <summary>
        /// The most frames one call completes or refines (a sequence, a shot): about 9.7 hours at 30
        /// frames per second. A longer one is refused before anything is allocated.
        /// </summary>
        public const int ZOO_MAX_FRAMES = 1048576;

        /// <summary>
        /// The longest window <c>zoo_stitch_set_window</c> plans (frames).
        /// </summary>
        public const int ZOO_MAX_WINDOW = 4096;

        /// <summary>
        /// The version of this library's C ABI: <c>ZOO_ABI_VERSION</c> of the header it was built with.
        /// Thread-safe.
        /// </summary>
        [DllImport(Library, EntryPoint = "zoo_abi_version", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern uint zoo_abi_version();

        /// <summary>
        /// Loads a model exported by <c>zoo export --onnx</c> (any task: transition, keyframes, stitch,
        /// synthesis) from the file <c>path</c> (UTF-8, NUL-terminated) into <c>*out</c>; a <c>zoo export --portable</c>
        /// main file is loaded with the companion files beside it. <c>zoo_model_task</c> says what it does.
        /// A file that is not an exported model, of a format version this library does not read, or a
        /// bare step graph with no task is <c>ZOO_STATUS_LOAD_FAILED</c> with a message naming the fix. Free
        /// the model with <c>zoo_model_free</c>. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>path</c> is NULL or a NUL-terminated string; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_load", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_model_load(byte* path, ZooModel** @out);

        /// <summary>
        /// Loads a model from memory: <c>bytes</c> holds the <c>bytes_len</c> bytes of a file written by `zoo export
        /// --onnx` (read from an archive, an APK's assets, a resource pack...), with the same checks as
        /// <c>zoo_model_load</c> and the same model as loading that file (a <c>--portable</c> export, whose
        /// weights are in companion files, loads from its files only). The library keeps no pointer to
        /// <c>bytes</c>: free or reuse them when the call returns. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>bytes</c> is NULL or holds <c>bytes_len</c> readable bytes; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_load_memory", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_model_load_memory(byte* bytes, UIntPtr bytes_len, ZooModel** @out);

        /// <summary>
        /// Frees a model from <c>zoo_model_load</c> (NULL is ignored). Runners, characters and streams made
        /// from it keep what they need, so they may be freed before or after it.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a pointer from <c>zoo_model_load</c> not freed before and not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_model_free(ZooModel* model);

        /// <summary>
        /// The task of <c>model</c>: which functions run it. <c>ZOO_TASK_NONE</c> for a NULL handle (the last
        /// error says so). Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_task", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooTask zoo_model_task(ZooModel* model);

        /// <summary>
        /// Writes what every model is (task, joints, frame rate, units and axes) into <c>*out</c>.
        /// Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_info", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_model_info(ZooModel* model, ZooModelInfo* @out);

        /// <summary>
        /// Writes the model's skeleton: <c>parents</c> receives <c>K</c> parent indices (-1 for the root, every
        /// parent before its child) and <c>offsets</c> <c>3K</c> rest offsets from the parent (model units), both
        /// in the joint order of every pose (<c>K</c>: <c>zoo_model_info</c>'s <c>joints</c>). Poses given to a
        /// stitching model must have these bone lengths. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; each buffer is NULL or holds its given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_skeleton", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_model_skeleton(ZooModel* model, int* parents, UIntPtr parents_len, float* offsets, UIntPtr offsets_len);

        /// <summary>
        /// Copies the name of joint <c>joint</c> of the model's skeleton (UTF-8, the training clips' joint
        /// name) into <c>buffer</c> (at most <c>capacity</c> bytes, NUL-terminated, truncated if needed) and writes
        /// its full length in bytes without the NUL into <c>*length</c>; <c>buffer</c> NULL with <c>capacity</c> 0 asks
        /// for the length. Joints are in the order of every pose (<c>joint</c> &lt; <c>zoo_model_info</c>'s
        /// <c>joints</c>): an engine maps its bones to them by name. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>buffer</c> is NULL or valid for <c>capacity</c> bytes of writes;
        /// <c>length</c> is NULL or writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_model_joint_name", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_model_joint_name(ZooModel* model, UIntPtr joint, byte* buffer, UIntPtr capacity, UIntPtr* length);

        /// <summary>
        /// Writes what a transition model expects into <c>*out</c>. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_info", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_info(ZooModel* model, ZooTransitionInfo* @out);

        /// <summary>
        /// The terrain patch of a terrain-aware transition model: <c>*side</c> samples per side on a square
        /// of <c>*extent</c> model units around the root. <c>ZOO_STATUS_NOT_AVAILABLE</c> for a model without
        /// terrain input (a flat-ground model). Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>side</c> and <c>extent</c> are NULL or writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_terrain", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_terrain(ZooModel* model, UIntPtr* side, float* extent);

        /// <summary>
        /// Creates scratch space for running <c>model</c> for up to <c>max_batch</c> characters per call
        /// (1..<c>ZOO_MAX_BATCH</c>; a larger batch is refused), on one thread at a time, into <c>*out</c>; free it with
        /// <c>zoo_transition_runner_free</c>. Transitions longer than the trained length are refused unless
        /// <c>zoo_transition_allow_beyond_trained</c>. Thread-safe (the model is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_runner_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_runner_new(ZooModel* model, UIntPtr max_batch, ZooTransitionRunner** @out);

        /// <summary>
        /// Frees a runner (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or a pointer from <c>zoo_transition_runner_new</c> not freed before and not in
        /// use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_runner_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_transition_runner_free(ZooTransitionRunner* runner);

        /// <summary>
        /// Whether <c>runner</c> accepts transitions longer than the model was trained for (off by default:
        /// beyond its training length the network drifts from the target).
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or a live runner used by this thread only.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_allow_beyond_trained", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_allow_beyond_trained(ZooTransitionRunner* runner, [MarshalAs(UnmanagedType.U1)] bool allow);

        /// <summary>
        /// Creates the transition states of <c>count</c> characters of <c>model</c> into <c>*out</c>; free them with
        /// <c>zoo_transition_characters_free</c>. Thread-safe (the model is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_characters_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_characters_new(ZooModel* model, UIntPtr count, ZooTransitionCharacters** @out);

        /// <summary>
        /// Frees characters (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or a pointer from <c>zoo_transition_characters_new</c> not freed before and
        /// not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_characters_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_transition_characters_free(ZooTransitionCharacters* characters);

        /// <summary>
        /// Starts a transition of <c>length</c> frames for every character from global joint positions:
        /// <c>past</c> holds <c>N * frames * 3K</c> values (the same number of context frames per character, at
        /// least one; the model was trained with <c>ZooTransitionInfo</c>'s <c>past_frames</c>), <c>target</c> and
        /// <c>next</c> <c>N * 3K</c> each (the target pose and the pose after it). <c>length</c> is the number of
        /// frames before the target frame; pass <c>transition_frames</c> for the trained length. Then step it
        /// with <c>zoo_transition_step</c>. Cost: one graph pass per context frame, all in this call (ten
        /// steps' worth for the paper's model); to spread them over the frames the game plays, use
        /// <c>zoo_transition_begin</c> and <c>zoo_transition_feed</c>. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_start", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_start(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, float* past, UIntPtr past_len, float* target, UIntPtr target_len, float* next, UIntPtr next_len, UIntPtr length);

        /// <summary>
        /// Begins a transition of <c>length</c> frames for every character whose context the game feeds
        /// frame by frame as it plays it, so that no call encodes the whole context at once (a frame
        /// budget; <c>zoo_transition_start</c> runs one graph pass per context frame in one call): <c>first</c>
        /// holds each character's first context frame (<c>N * 3K</c> global positions), <c>target</c> and <c>next</c>
        /// as in <c>zoo_transition_start</c>, <c>past_frames</c> the context frames in all (the model was
        /// trained with <c>ZooTransitionInfo</c>'s <c>past_frames</c>). Runs no graph pass (one when
        /// <c>past_frames</c> is 1; for one character, the start graph's part that needs only the target).
        /// Then call <c>zoo_transition_feed</c> once per frame for the other
        /// <c>past_frames - 1</c> context frames (one graph pass each, and the start graph with the first) and
        /// step. For one character the runner spreads these passes over the calls, node by node.
        /// The frames are those <c>zoo_transition_start</c> gives for the same context, bit for bit. One
        /// thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_begin", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_begin(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, float* first, UIntPtr first_len, float* target, UIntPtr target_len, float* next, UIntPtr next_len, UIntPtr past_frames, UIntPtr length);

        /// <summary>
        /// Feeds the next context frame of every character's transition begun with
        /// <c>zoo_transition_begin</c>: <c>frame</c> holds <c>N * 3K</c> global positions. One graph pass (and the start
        /// graph on the first context frame, with the second); for one character the pass may finish in
        /// the next call (a frame budget). After the last one, step the transition. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; <c>frame</c> is NULL or holds
        /// <c>frame_len</c> floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_feed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_feed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, float* frame, UIntPtr frame_len);

        /// <summary>
        /// <c>zoo_transition_begin</c> from engine poses: <c>first_roots</c>, <c>target_roots</c> and <c>next_roots</c> hold
        /// one root per character (<c>N</c>), the rotation buffers <c>N * 4K</c> values; then
        /// <c>zoo_transition_feed_posed</c> per context frame and <c>zoo_transition_step_posed</c>. One thread at a
        /// time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_begin_posed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_begin_posed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, ZooRootMotion* first_roots, UIntPtr first_roots_len, float* first_rotations, UIntPtr first_rotations_len, ZooRootMotion* target_roots, UIntPtr target_roots_len, float* target_rotations, UIntPtr target_rotations_len, ZooRootMotion* next_roots, UIntPtr next_roots_len, float* next_rotations, UIntPtr next_rotations_len, UIntPtr past_frames, UIntPtr length);

        /// <summary>
        /// <c>zoo_transition_feed</c> from engine poses: one root per character (<c>N</c>) and <c>N * 4K</c> rotation
        /// values. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_feed_posed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_feed_posed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, ZooRootMotion* roots, UIntPtr roots_len, float* rotations, UIntPtr rotations_len);

        /// <summary>
        /// The next frame of every character's transition into <c>poses</c> (<c>N * 3K</c> global positions): the
        /// target-blended frames, the last one the target. Stepping past the target frame is
        /// <c>ZOO_STATUS_INVALID_STATE</c>. Cost: one graph pass per character, two in the few steps before
        /// the blend window (the blend needs the network's own target frame, computed ahead; staggered
        /// across a batch). One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; <c>poses</c> is NULL or holds <c>poses_len</c>
        /// writable floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_step", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_step(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, float* poses, UIntPtr poses_len);

        /// <summary>
        /// Starts a transition of <c>length</c> frames for every character from engine poses: each pose is a
        /// <c>ZooRootMotion</c> and <c>4K</c> rotation values. <c>past_roots</c> holds <c>N * frames</c> roots (the same
        /// number of context frames per character, character-major) and <c>past_rotations</c> <c>4K</c> values
        /// per root; <c>target_roots</c> and <c>next_roots</c> one root per character (<c>N</c>), <c>target_rotations</c>
        /// and <c>next_rotations</c> <c>N * 4K</c> values. Every root must be finite and every rotation a finite,
        /// non-zero quaternion. Then <c>zoo_transition_step_posed</c>. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_start_posed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_start_posed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, ZooRootMotion* past_roots, UIntPtr past_roots_len, float* past_rotations, UIntPtr past_rotations_len, ZooRootMotion* target_roots, UIntPtr target_roots_len, float* target_rotations, UIntPtr target_rotations_len, ZooRootMotion* next_roots, UIntPtr next_roots_len, float* next_rotations, UIntPtr next_rotations_len, UIntPtr length);

        /// <summary>
        /// The next frame of every character's transition (started with
        /// <c>zoo_transition_start_posed</c>) as engine poses: <c>roots</c> receives <c>N</c> <c>ZooRootMotion</c> and
        /// <c>rotations</c> <c>N * 4K</c> local rotations (the hips' relative to the root), fitted to the
        /// network's frame inside the runtime. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length of writable values.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_step_posed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_step_posed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, ZooRootMotion* roots, UIntPtr roots_len, float* rotations, UIntPtr rotations_len);

        /// <summary>
        /// A whole transition of <c>length</c> frames for every character from engine poses, in one call:
        /// the inputs as in <c>zoo_transition_start_posed</c>, then <c>out_roots</c> receives <c>N * (length + 1)</c>
        /// roots and <c>out_rotations</c> <c>4K</c> rotations per root (character-major: each character's
        /// <c>length</c> frames, then its target frame). <c>fallback</c> 1 moves a transition that misses its
        /// target by more than the model's calibrated thresholds towards the interpolation (the model's
        /// thresholds for this length; <c>zoo transition</c>'s default), 0 keeps the network's; <c>foot_lock</c> 1
        /// locks the feet (<c>zoo transition --foot-lock</c>), 0 does not. The frames are those `zoo
        /// transition --in-place` writes for the same poses. Only a whole transition gets the fallback
        /// and the foot lock (both look at the whole transition); with both 0 the frames are those of
        /// <c>zoo_transition_start_posed</c> and <c>length + 1</c> calls of <c>zoo_transition_step_posed</c> (bit for bit
        /// for one character; for several, up to the rounding of batched kernels). The
        /// transitions are finished afterwards. Cost: every pass of the transition in this call. One
        /// thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length (the outputs writable).
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_generate_posed", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_generate_posed(ZooTransitionRunner* runner, ZooTransitionCharacters* characters, ZooRootMotion* past_roots, UIntPtr past_roots_len, float* past_rotations, UIntPtr past_rotations_len, ZooRootMotion* target_roots, UIntPtr target_roots_len, float* target_rotations, UIntPtr target_rotations_len, ZooRootMotion* next_roots, UIntPtr next_roots_len, float* next_rotations, UIntPtr next_rotations_len, UIntPtr length, byte fallback, byte foot_lock, ZooRootMotion* out_roots, UIntPtr out_roots_len, float* out_rotations, UIntPtr out_rotations_len);

        /// <summary>
        /// Sets the ground under character <c>index</c>: a heightmap of <c>cols * rows</c> heights (model units,
        /// Y up) on a regular grid in the XZ plane, sample <c>(i, k)</c> at `(origin_x + i * cell, origin_z +
        /// k * cell)<c> stored at </c>heights[k * cols + i]`, bilinear between samples and extended beyond
        /// the border (the <c>zoo-heightfield</c> layout of <c>zoo data synth --terrain</c>). The map is copied.
        /// A terrain-aware model (<c>zoo_transition_terrain</c>) needs it before <c>zoo_transition_start</c>
        /// or <c>zoo_transition_start_posed</c>; a flat-ground model ignores it. <c>heights</c> NULL with
        /// <c>heights_len</c> 0 removes the ground. Takes effect at the next step. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or live and used by this thread only; <c>heights</c> is NULL or holds
        /// <c>heights_len</c> floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_set_heightmap", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_set_heightmap(ZooTransitionCharacters* characters, UIntPtr index, UIntPtr cols, UIntPtr rows, float cell, float origin_x, float origin_z, float* heights, UIntPtr heights_len);

        /// <summary>
        /// Frames character <c>index</c>'s transition still returns (0 once it returned its target frame).
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or live and used by this thread only; <c>out</c> is NULL or writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_frames_left", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_frames_left(ZooTransitionCharacters* characters, UIntPtr index, UIntPtr* @out);

        /// <summary>
        /// How far the network's own target frame for character <c>index</c> lay from the requested target
        /// before the blend hid it (mean and largest joint distance, model units): a cue to fall back
        /// to inertialization. <c>ZOO_STATUS_NOT_AVAILABLE</c> before stepping reaches the blend window.
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or live and used by this thread only; <c>mean</c> and <c>max</c> are NULL or
        /// writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_transition_target_miss", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_transition_target_miss(ZooTransitionCharacters* characters, UIntPtr index, float* mean, float* max);

        /// <summary>
        /// Writes what a keyframes model expects into <c>*out</c>. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_keyframes_info", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_keyframes_info(ZooModel* model, ZooKeyframesInfo* @out);

        /// <summary>
        /// Creates scratch space for completing the keys of up to <c>max_batch</c> characters per call, on
        /// one thread at a time, into <c>*out</c>; free it with <c>zoo_keyframes_runner_free</c>. Thread-safe
        /// (the model is shared); the runner keeps what it needs of the model.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_keyframes_runner_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_keyframes_runner_new(ZooModel* model, UIntPtr max_batch, ZooKeyframesRunner** @out);

        /// <summary>
        /// Frees a runner (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or a pointer from <c>zoo_keyframes_runner_new</c> not freed before and not in
        /// use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_keyframes_runner_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_keyframes_runner_free(ZooKeyframesRunner* runner);

        /// <summary>
        /// Completes one character's keys into <c>out</c>: <c>key_frames</c> holds the key frames (strictly
        /// increasing, the first 0, below <c>ZOO_MAX_FRAMES</c>), <c>poses</c> <c>key_frames_len * D</c> floats (one
        /// pose per key; <c>D</c> is <c>ZooKeyframesInfo</c>'s <c>frame_values</c>), <c>fixed</c> NULL
        /// and 0 for whole keys or <c>key_frames_len * G</c> flags (<c>uint8_t</c>, 1 or 0) for partial keys (a model with key groups
        /// only; the first key fixes every group), <c>out</c> <c>(key_frames[key_frames_len - 1] + 1) * D</c> floats. Keys
        /// and buffers are checked before anything is written. Every key frame of <c>out</c> equals its key
        /// (in the groups it fixes): the network's miss is spread over the frames before it. A humanoid
        /// model's completion (key groups, a skeleton with joints named <c>foot</c>) then has its feet locked
        /// between the keys, key frames unchanged, as <c>zoo complete</c> does. The runner: one thread at a
        /// time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or live and used by this thread only; each buffer is NULL or holds its given
        /// length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_keyframes_complete", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_keyframes_complete(ZooKeyframesRunner* runner, UIntPtr* key_frames, UIntPtr key_frames_len, float* poses, UIntPtr poses_len, byte* @fixed, UIntPtr fixed_len, float* @out, UIntPtr out_len);

        /// <summary>
        /// Completes the keys of <c>count</c> characters together (at most the runner's <c>max_batch</c>; an
        /// ARNN step graph runs one graph call per frame, the in-betweening design one call per
        /// character): character <c>c</c> has <c>key_counts[c]</c> keys, and <c>key_frames</c>, <c>poses</c>, <c>fixed</c> and
        /// <c>out</c> hold the characters' buffers of <c>zoo_keyframes_complete</c> one after the other
        /// (character-major; <c>fixed</c> NULL and 0 when every key is whole). A character's frames are
        /// those it gets alone. The runner: one thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or live and used by this thread only; each buffer is NULL or holds its given
        /// length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_keyframes_complete_batch", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_keyframes_complete_batch(ZooKeyframesRunner* runner, UIntPtr* key_counts, UIntPtr count, UIntPtr* key_frames, UIntPtr key_frames_len, float* poses, UIntPtr poses_len, byte* @fixed, UIntPtr fixed_len, float* @out, UIntPtr out_len);

        /// <summary>
        /// Writes what a stitching model expects into <c>*out</c> (for the window it is planned for).
        /// Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_info", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_info(ZooModel* model, ZooStitchInfo* @out);

        /// <summary>
        /// Plans the model for another window <c>w</c> and stride <c>s</c> (<c>1 &lt;= s &lt;= w</c>; shorter windows give
        /// streams less latency, at the quality the stitching benchmark measures for them). Not
        /// thread-safe: no other thread may use the model during the call, and streams made from it
        /// must be freed first (<c>ZOO_STATUS_INVALID_STATE</c> otherwise).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model used by no other thread during the call.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_set_window", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_set_window(ZooModel* model, UIntPtr window, UIntPtr stride);

        /// <summary>
        /// Writes into <c>*out</c> whether the model was trained on clips inertialized at their seams
        /// (<c>zoo train rmr</c>'s default since 2026-11-28; the file's <c>stitch.pre_blend</c>): refine such a
        /// model's sequences with <c>zoo_stitch_refine_at_seams</c> and mark a stream's seams
        /// (<c>zoo_stitch_stream_mark_seam</c>), as <c>zoo stitch</c> does. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_pre_blend", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_pre_blend(ZooModel* model, bool* @out);

        /// <summary>
        /// Switches the seam guard of <c>zoo_stitch_refine_at_seams</c> on (the default, as <c>zoo stitch</c>)
        /// or off: where the refined motion, after the ankle IK, moves a joint faster within 5 frames
        /// of a seam than the inertialized input does there, it is blended towards itself smoothed until
        /// it does not, before the foot lock. Not thread-safe, as <c>zoo_stitch_set_window</c>: no other
        /// thread may use the model during the call, and streams made from it must be freed first.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model used by no other thread during the call.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_set_seam_guard", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_set_seam_guard(ZooModel* model, [MarshalAs(UnmanagedType.U1)] bool on);

        /// <summary>
        /// Sets the seams' reach of <c>zoo_stitch_refine_at_seams</c> and of the streams made afterwards:
        /// frames <c>frames</c> or more from every seam are left as they were given, frames within half of
        /// it are the refined output, eased from one to the other between (each stretch near seams first
        /// moved on the ground to start on the input's ground root), as <c>zoo stitch --seam-reach</c> does.
        /// 0 refines the whole sequence (<c>zoo stitch --refine-everywhere</c>). Default: the model's window,
        /// as <c>zoo stitch</c>. A stream with a reach passes the frames away from every marked seam through
        /// as they were pushed. Not thread-safe, as <c>zoo_stitch_set_window</c>.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model used by no other thread during the call.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_set_seam_reach", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_set_seam_reach(ZooModel* model, UIntPtr frames);

        /// <summary>
        /// Writes into <c>*out</c> the seams' reach of <c>zoo_stitch_set_seam_reach</c> (0: the whole sequence is
        /// refined). Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_seam_reach", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_seam_reach(ZooModel* model, UIntPtr* @out);

        /// <summary>
        /// Refines a whole aligned sequence of <c>frames</c> poses (<c>roots</c> holds <c>frames</c> roots, <c>rotations</c>
        /// <c>frames * 4K</c> floats; at least <c>window</c> frames) into <c>out_roots</c> / <c>out_rotations</c> (the same
        /// sizes, root deltas filled, zero on the first frame) and the predicted contacts into
        /// <c>contacts</c> (<c>frames * 4</c> bytes). <c>place_ankles</c> puts the ankles where the refiner predicts
        /// them and <c>lock_feet</c> locks the planted feet by the predicted contacts (both on: what
        /// <c>zoo stitch</c> writes). Allocates the sequence's scratch space per call. Thread-safe: threads may
        /// refine with one model at once.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; each buffer is NULL or holds its given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_refine", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_refine(ZooModel* model, ZooRootMotion* roots, UIntPtr frames, float* rotations, UIntPtr rotations_len, [MarshalAs(UnmanagedType.U1)] bool place_ankles, [MarshalAs(UnmanagedType.U1)] bool lock_feet, ZooRootMotion* out_roots, UIntPtr out_roots_len, float* out_rotations, UIntPtr out_rotations_len, byte* contacts, UIntPtr contacts_len);

        /// <summary>
        /// <c>zoo_stitch_refine</c> of the sequence inertialized at <c>seams</c> first (<c>seams_len</c> frame
        /// indices where a clip starts, each below <c>frames</c>): from each seam on, the jump to the
        /// previous clip decays over <c>blend_frames</c> frames before the refiner runs (`zoo stitch
        /// --pre-blend<c>; what a model trained on inertialized seams needs: </c>zoo_stitch_pre_blend`).
        /// Seams on frames 0, 1 and the last change nothing. With seams given, the seams are also
        /// guarded against pops after the ankle IK (<c>zoo_stitch_set_seam_guard</c>). Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; each buffer is NULL or holds its given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_refine_at_seams", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_refine_at_seams(ZooModel* model, ZooRootMotion* roots, UIntPtr frames, float* rotations, UIntPtr rotations_len, UIntPtr* seams, UIntPtr seams_len, [MarshalAs(UnmanagedType.U1)] bool place_ankles, [MarshalAs(UnmanagedType.U1)] bool lock_feet, ZooRootMotion* out_roots, UIntPtr out_roots_len, float* out_rotations, UIntPtr out_rotations_len, byte* contacts, UIntPtr contacts_len);

        /// <summary>
        /// Creates a stitching stream over <c>model</c> into <c>*out</c>; free it with
        /// <c>zoo_stitch_stream_free</c>. Thread-safe (the model is shared); the stream: one thread at a
        /// time. Runs one window of the refiner on zeros (about a window's time: a few milliseconds for
        /// a paper-size model), so that no per-frame call makes the stream's buffers.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_new(ZooModel* model, ZooStitchStream** @out);

        /// <summary>
        /// Frees a stream (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or a pointer from <c>zoo_stitch_stream_new</c> not freed before and not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_stitch_stream_free(ZooStitchStream* stream);

        /// <summary>
        /// Pushes the next frame of the aligned motion: one pose, <c>root</c> and <c>4K</c> floats of
        /// <c>rotations</c>. Runs a window when one is due. Pushing after <c>zoo_stitch_stream_finish</c> is
        /// <c>ZOO_STATUS_INVALID_STATE</c>. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only; <c>root</c> is NULL or readable; <c>rotations</c>
        /// is NULL or holds <c>rotations_len</c> floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_push", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_push(ZooStitchStream* stream, ZooRootMotion* root, float* rotations, UIntPtr rotations_len);

        /// <summary>
        /// Sets what follows the refiner in <c>stream</c>, before its first push (<c>ZOO_STATUS_INVALID_STATE</c>
        /// after): <c>place_ankles</c> puts the ankles where the refiner predicts them, <c>lock_feet</c> locks the
        /// planted feet by the predicted contacts (both on by default, as <c>zoo stitch</c>); the seam guard
        /// and the seams' reach follow the model's (<c>zoo_stitch_set_seam_guard</c>,
        /// <c>zoo_stitch_set_seam_reach</c>). Both off with the guard and the reach off: the refiner's poses
        /// as they are, at a latency of <c>window + stride - 1</c> frames. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_set_cleanup", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_set_cleanup(ZooStitchStream* stream, [MarshalAs(UnmanagedType.U1)] bool place_ankles, [MarshalAs(UnmanagedType.U1)] bool lock_feet);

        /// <summary>
        /// Writes into <c>*out</c> the stream's latency in frames: the refined pose of frame <c>t</c> is ready
        /// once frame <c>t + latency</c> is pushed. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only; <c>out</c> is NULL or writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_latency", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_latency(ZooStitchStream* stream, UIntPtr* @out);

        /// <summary>
        /// Writes into <c>*ready</c> whether the next refined pose can be popped. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only; <c>ready</c> is NULL or writable.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_ready", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_ready(ZooStitchStream* stream, bool* ready);

        /// <summary>
        /// Pops the next refined pose into <c>root</c> and <c>rotations</c> (<c>4K</c> floats; root deltas from the
        /// previous popped pose) and its predicted contacts into <c>contacts</c> (4 bytes). Before it is
        /// ready (fewer than <c>latency</c> frames pushed after it, and not finished) the call is
        /// <c>ZOO_STATUS_NOT_AVAILABLE</c> and writes nothing. The pose has the ankle IK, the seam guard and
        /// the foot lock of <c>zoo stitch</c> unless <c>zoo_stitch_stream_set_cleanup</c> turned them off. One
        /// thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only; <c>root</c> is NULL or writable; each buffer
        /// is NULL or holds its given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_pop", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_pop(ZooStitchStream* stream, ZooRootMotion* root, float* rotations, UIntPtr rotations_len, byte* contacts, UIntPtr contacts_len);

        /// <summary>
        /// Marks the next pushed pose as the first frame of a new clip: the stream inertializes the seam
        /// before refining and guards it, as <c>zoo_stitch_refine_at_seams</c> does (the seam frame is
        /// encoded once the frame after it is pushed). A seam on frame 0 or 1 is not inertialized. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_mark_seam", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_mark_seam(ZooStitchStream* stream);

        /// <summary>
        /// Ends the motion: runs the window ending on the last frame and makes every remaining frame
        /// ready to pop. Needs at least <c>window</c> frames pushed (<c>ZOO_STATUS_INVALID_STATE</c> before);
        /// finishing twice does nothing. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>stream</c> is NULL or live and used by this thread only.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_stitch_stream_finish", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_stitch_stream_finish(ZooStitchStream* stream);

        /// <summary>
        /// Writes what a synthesis model expects into <c>*out</c>. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_info", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_info(ZooModel* model, ZooSynthesisInfo* @out);

        /// <summary>
        /// Whether runners and characters made from <c>model</c> from now on (synthesis and control) run
        /// the file's refiner behind the generator when it has one (<c>refine</c>, the default after
        /// loading) or the generator's own frames. Those made before keep theirs. Not thread-safe: no
        /// other thread may use the model during the call.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model used by no other thread during the call.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_set_refine", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_set_refine(ZooModel* model, [MarshalAs(UnmanagedType.U1)] bool refine);

        /// <summary>
        /// Writes the training data's mean feature frame (<c>D</c> floats, clip units) into <c>frame</c>: a
        /// neutral start frame for an engine that has no encoded frame of its own. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>frame</c> is NULL or holds <c>frame_len</c> writable floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_mean_frame", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_mean_frame(ZooModel* model, float* frame, UIntPtr frame_len);

        /// <summary>
        /// Creates scratch space for stepping up to <c>max_batch</c> characters of <c>model</c> per call
        /// (1..<c>ZOO_MAX_BATCH</c>; a larger batch is refused) on one thread at a time into <c>*out</c>; free it with
        /// <c>zoo_synthesis_runner_free</c>. Thread-safe (the model is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_runner_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_runner_new(ZooModel* model, UIntPtr max_batch, ZooSynthesisRunner** @out);

        /// <summary>
        /// Frees a runner (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or a pointer from <c>zoo_synthesis_runner_new</c> not freed before and not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_runner_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_synthesis_runner_free(ZooSynthesisRunner* runner);

        /// <summary>
        /// Creates <c>count</c> characters of <c>model</c>, character <c>c</c> seeded with <c>seeds[c]</c>, into <c>*out</c>;
        /// start them with <c>zoo_synthesis_start</c>, free them with <c>zoo_synthesis_characters_free</c>.
        /// Thread-safe (the model is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>seeds</c> is NULL or holds <c>count</c> values; <c>out</c> is NULL or
        /// valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_characters_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_characters_new(ZooModel* model, ulong* seeds, UIntPtr count, ZooSynthesisCharacters** @out);

        /// <summary>
        /// Frees characters (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or a pointer from <c>zoo_synthesis_characters_new</c> not freed before and
        /// not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_characters_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_synthesis_characters_free(ZooSynthesisCharacters* characters);

        /// <summary>
        /// Starts every character from a feature frame (<c>frames</c>: <c>N * D</c> floats, clip units,
        /// character-major) with its root at <c>(x, z)</c> facing <c>yaw</c> (radians about +Y; <c>placements</c>: <c>N * 3</c>
        /// floats, <c>x z yaw</c> per character), from the zero generator state. The random numbers are not
        /// reset. Everything is checked before any character changes. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_start", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_start(ZooSynthesisCharacters* characters, float* frames, UIntPtr frames_len, float* placements, UIntPtr placements_len);

        /// <summary>
        /// Generates the next frame of every character in one graph run: <c>roots</c> receives <c>N</c> roots,
        /// <c>rotations</c> <c>N * 4K</c> floats and <c>contacts</c> <c>N * 2</c> bytes (left, right foot). <c>temperature</c>
        /// scales the mixture's standard deviations (1: the model's; finite, &gt;= 0). Stepping before
        /// <c>zoo_synthesis_start</c> is <c>ZOO_STATUS_INVALID_STATE</c>. Allocates nothing per frame (without a
        /// refiner). Runner and characters: one thread at a time each.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length of writable values.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_synthesis_step", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_synthesis_step(ZooSynthesisRunner* runner, ZooSynthesisCharacters* characters, float temperature, ZooRootMotion* roots, UIntPtr roots_len, float* rotations, UIntPtr rotations_len, byte* contacts, UIntPtr contacts_len);

        /// <summary>
        /// Writes the default settings into <c>*out</c> (batches of 3 frames, 5 x 5 candidates, the default
        /// offsets as NULL). Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_settings_default", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_control_settings_default(ZooControlSettings* @out);

        /// <summary>
        /// Creates scratch space for stepping up to <c>max_batch</c> controlled characters of <c>model</c> per call
        /// (1..<c>ZOO_MAX_BATCH</c>; a larger batch is refused) on one thread at a time
        /// into <c>*out</c>; free it with <c>zoo_control_runner_free</c>. Thread-safe (the model is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_runner_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_control_runner_new(ZooModel* model, UIntPtr max_batch, ZooControlRunner** @out);

        /// <summary>
        /// Frees a runner (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>runner</c> is NULL or a pointer from <c>zoo_control_runner_new</c> not freed before and not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_runner_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_control_runner_free(ZooControlRunner* runner);

        /// <summary>
        /// Creates <c>count</c> controlled characters of <c>model</c>, character <c>c</c> seeded with <c>seeds[c]</c>,
        /// planning with <c>settings</c> (NULL: the defaults; checked) into <c>*out</c>; start them with
        /// <c>zoo_control_start</c>, free them with <c>zoo_control_characters_free</c>. Thread-safe (the model
        /// is shared).
        /// </summary>
        /// <remarks>
        /// Safety: <c>model</c> is NULL or a live model; <c>seeds</c> is NULL or holds <c>count</c> values; <c>settings</c> is NULL
        /// or readable (its offsets NULL or holding their lengths); <c>out</c> is NULL or valid for a write.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_characters_new", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_control_characters_new(ZooModel* model, ulong* seeds, UIntPtr count, ZooControlSettings* settings, ZooControlCharacters** @out);

        /// <summary>
        /// Frees controlled characters (NULL is ignored).
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or a pointer from <c>zoo_control_characters_new</c> not freed before and
        /// not in use.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_characters_free", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern void zoo_control_characters_free(ZooControlCharacters* characters);

        /// <summary>
        /// Starts every character from its seed frames: <c>frames</c> holds <c>N * F * D</c> floats (<c>F &gt;= 1</c>
        /// feature frames per character, the same <c>F</c> for all, oldest first, clip units,
        /// character-major), the last one the current frame, with the root at <c>(x, z)</c> facing <c>yaw</c>
        /// (<c>placements</c>: <c>x z yaw</c> per character). Drops any plan; the random numbers are not reset.
        /// Everything is checked before any character changes. One thread at a time.
        /// </summary>
        /// <remarks>
        /// Safety: <c>characters</c> is NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_start", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_control_start(ZooControlCharacters* characters, float* frames, UIntPtr frames_len, float* placements, UIntPtr placements_len);

        /// <summary>
        /// Plays every character's next frame under its control (<c>controls</c>: one per character) into
        /// <c>roots</c> (<c>N</c>), <c>rotations</c> (<c>N * 4K</c> floats) and <c>contacts</c> (<c>N * 2</c> bytes: left, right
        /// foot). Stepping before <c>zoo_control_start</c> is <c>ZOO_STATUS_INVALID_STATE</c>; a bad control is
        /// refused before any character moves. Runner and characters: one thread at a time each.
        /// </summary>
        /// <remarks>
        /// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
        /// given length.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_control_step", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_control_step(ZooControlRunner* runner, ZooControlCharacters* characters, ZooControl* controls, UIntPtr controls_len, ZooRootMotion* roots, UIntPtr roots_len, float* rotations, UIntPtr rotations_len, byte* contacts, UIntPtr contacts_len);

        /// <summary>
        /// Converts engine poses in place from frame <c>from</c> to frame <c>to</c>, as the runtime's
        /// <c>EnginePose::convert</c> does: in each of the <c>roots_len</c> roots, <c>root_position</c>,
        /// <c>delta_position</c> and <c>hips_position</c> are scaled and re-axed, <c>root_rotation</c> is conjugated by
        /// the change of axes and <c>delta_yaw</c> is reversed by a change of handedness; each rotation of
        /// <c>rotations</c> (<c>x y z w</c>, <c>rotations_len</c> a multiple of 4: <c>4K</c> per root) is conjugated too.
        /// <c>roots</c> NULL with <c>roots_len</c> 0 converts rotations only, <c>rotations</c> NULL with
        /// <c>rotations_len</c> 0 roots only. Convert a model's poses to the engine's after a call that
        /// writes them (<c>from</c>: the model's frame from <c>zoo_model_info</c>) and the engine's to the model's
        /// before a call that reads them. Allocates nothing. Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>from</c> and <c>to</c> are NULL or readable; each buffer is NULL or holds its given length of
        /// writable values.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_pose_convert", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_pose_convert(ZooCoordinateFrame* from, ZooCoordinateFrame* to, ZooRootMotion* roots, UIntPtr roots_len, float* rotations, UIntPtr rotations_len);

        /// <summary>
        /// Converts positions in place from frame <c>from</c> to frame <c>to</c>: <c>positions</c> holds <c>x y z</c>
        /// triples (<c>positions_len</c> a multiple of 3), each scaled and re-axed as the runtime's
        /// <c>Conversion::position</c> does: global joint positions of <c>zoo_transition_start</c> /
        /// <c>zoo_transition_step</c>, the rest offsets of <c>zoo_model_skeleton</c>. Allocates nothing.
        /// Thread-safe.
        /// </summary>
        /// <remarks>
        /// Safety: <c>from</c> and <c>to</c> are NULL or readable; <c>positions</c> is NULL or holds <c>positions_len</c> writable
        /// floats.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_positions_convert", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_positions_convert(ZooCoordinateFrame* from, ZooCoordinateFrame* to, float* positions, UIntPtr positions_len);

        /// <summary>
        /// Copies the calling thread's last error message into <c>buffer</c> (at most <c>capacity</c> bytes,
        /// NUL-terminated, truncated if needed) and returns the message's full length in bytes without
        /// the NUL. <c>buffer</c> may be NULL to ask for the length.
        /// </summary>
        /// <remarks>
        /// The contract: every function that returns a <c>ZooStatus</c> sets the calling thread's last error:
        /// it is empty (length 0) after <c>ZOO_STATUS_OK</c> and holds the failed call's message after any
        /// other status, until the thread's next such call. Functions that return no status (the <c>_free</c>
        /// functions, <c>zoo_model_task</c>, <c>zoo_abi_version</c>, <c>zoo_version_string</c>, <c>zoo_status_string</c>
        /// and this one) leave it as it is. Thread-safe: each thread has its own.
        /// Safety: <c>buffer</c> is NULL or valid for <c>capacity</c> bytes of writes.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_last_error", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern UIntPtr zoo_last_error(byte* buffer, UIntPtr capacity);

        /// <summary>
        /// The name of a status as a static NUL-terminated string (<c>"ZOO_STATUS_OK"</c>, ...), or
        /// <c>"ZOO_STATUS_UNKNOWN"</c> for a value that is not a <c>ZooStatus</c>. Never NULL; do not free it.
        /// Thread-safe. The status is passed as an integer so that any value is safe to pass.
        /// </summary>
        [DllImport(Library, EntryPoint = "zoo_status_string", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern byte* zoo_status_string(int status);

        /// <summary>
        /// The library's version as a static NUL-terminated string, <c>"zoo X.Y.Z (C ABI N)"</c>: the
        /// release of zoo it was built from and its <c>ZOO_ABI_VERSION</c>. Never NULL; do not free it.
        /// Thread-safe.
        /// </summary>
        [DllImport(Library, EntryPoint = "zoo_version_string", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern byte* zoo_version_string();

        /// <summary>
        /// Sends the library's log messages up to <c>max_level</c> (a <c>ZooLogLevel</c> value:
        /// <c>ZOO_LOG_LEVEL_WARNING</c> gives errors and warnings) to <c>callback</c>, with <c>user_data</c>; a NULL
        /// <c>callback</c> stops logging (the default: the library logs nothing, and never prints).
        /// Messages come from the library and the graph runtime it embeds (tract). Returns
        /// <c>ZOO_STATUS_INVALID_ARGUMENT</c> for a <c>max_level</c> outside <c>ZooLogLevel</c>, and
        /// <c>ZOO_STATUS_NOT_AVAILABLE</c> when the process already has another Rust logger (a Rust host
        /// that set its own <c>log</c> logger receives the messages there instead). Thread-safe; set it
        /// once at start-up.
        /// </summary>
        /// <remarks>
        /// Safety: <c>callback</c> is NULL or a function valid until it is replaced; <c>user_data</c> is what it
        /// expects.
        /// </remarks>
        [DllImport(Library, EntryPoint = "zoo_set_log_callback", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]
        public static extern ZooStatus zoo_set_log_callback(ZooLogCallback callback, void* user_data, int max_level);
    }
}
