// Transitions (RTN): zoo_transition_runner_*, zoo_transition_characters_*, start and step from
// global positions or from engine poses, heightmaps, frames left, target miss.
using System;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>Scratch space for running a transition model, on one thread at a time (<c>ZooTransitionRunner</c>).</summary>
    public sealed unsafe class TransitionRunner : ZooObject
    {
        TransitionRunner(ZooSafeHandle handle) : base(handle) { }

        /// <summary>
        /// A runner for batches of up to <paramref name="maxBatch"/> characters of <paramref name="model"/>
        /// (<c>zoo_transition_runner_new</c>; 1 to <see cref="ZooNative.ZOO_MAX_BATCH"/>): a larger batch is refused
        /// at its start and step, so size it from the largest <see cref="TransitionCharacters"/> it runs. A model of
        /// another task is refused.
        /// </summary>
        public TransitionRunner(Model model, int maxBatch) : this(Create(model, maxBatch)) { }

        static ZooSafeHandle Create(Model model, int maxBatch)
        {
            var batch = Size.Count(maxBatch, "maxBatch", "zoo_transition_runner_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_transition_runner_new((Native.ZooModel*)Enter(model, ref e), batch, (Native.ZooTransitionRunner**)&p), model);
                return Wrap(HandleKind.TransitionRunner, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>Whether transitions longer than the model was trained for are accepted (<c>zoo_transition_allow_beyond_trained</c>).</summary>
        public void AllowBeyondTrained(bool allow)
        {
            bool e = false;
            try { Errors.Check(ZooNative.zoo_transition_allow_beyond_trained((Native.ZooTransitionRunner*)Enter(this, ref e), allow), this); }
            finally { Exit(this, e); }
        }
    }

    /// <summary>
    /// The transitions of a batch of characters, on one thread at a time
    /// (<c>ZooTransitionCharacters</c>). Made with an engine frame (e.g.
    /// <see cref="ZooCoordinateFrame.Unity"/>), every pose and position in and out is in that frame,
    /// converted by the runtime; without one, in the model's. Steps allocate nothing.
    /// </summary>
    public sealed unsafe class TransitionCharacters : ZooObject
    {
        readonly int count;
        readonly int joints;
        readonly PoseConversion toModel;
        readonly PoseConversion toEngine;
        ZooRootMotion[] roots;
        float[] floats;

        TransitionCharacters(ZooSafeHandle handle, Model model, int count, ZooCoordinateFrame? engine) : base(handle)
        {
            this.count = count;
            joints = model.Joints;
            if (engine.HasValue)
            {
                toModel = new PoseConversion(engine.Value, model.Frame);
                toEngine = toModel.Inverse;
            }
        }

        /// <summary><paramref name="count"/> characters of <paramref name="model"/> (<c>zoo_transition_characters_new</c>; 1 to <see cref="ZooNative.ZOO_MAX_BATCH"/>); poses in <paramref name="engine"/>'s frame when given.</summary>
        public TransitionCharacters(Model model, int count, ZooCoordinateFrame? engine = null) : this(Create(model, count), model, count, engine) { }

        static ZooSafeHandle Create(Model model, int count)
        {
            var n = Size.Count(count, "count", "zoo_transition_characters_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_transition_characters_new((Native.ZooModel*)Enter(model, ref e), n, (Native.ZooTransitionCharacters**)&p), model);
                return Wrap(HandleKind.TransitionCharacters, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>Characters N in the batch.</summary>
        public int Count { get { ThrowIfDisposed("Count"); return count; } }

        /// <summary>Joints K of every pose.</summary>
        public int Joints { get { ThrowIfDisposed("Joints"); return joints; } }

        /// <summary>
        /// Starts a transition of <paramref name="length"/> frames from global joint positions
        /// (<c>zoo_transition_start</c>): <paramref name="past"/> N * frames * 3K, <paramref name="target"/>
        /// and <paramref name="next"/> N * 3K each.
        /// </summary>
        public void Start(TransitionRunner runner, ReadOnlySpan<float> past, ReadOnlySpan<float> target, ReadOnlySpan<float> next, int length)
        {
            var frames = Size.Count(length, "length", "zoo_transition_start");
            ToModelFrame(ref past, ref target, ref next);
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (float* p = &MemoryMarshal.GetReference(past))
                fixed (float* t = &MemoryMarshal.GetReference(target))
                fixed (float* n = &MemoryMarshal.GetReference(next))
                    s = ZooNative.zoo_transition_start(rp, cp, p, Size.Of(past.Length), t, Size.Of(target.Length), n, Size.Of(next.Length), frames);
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
        }

        /// <summary>
        /// Begins a transition of <paramref name="length"/> frames whose context is fed one frame
        /// per game frame (<c>zoo_transition_begin</c>), so that no frame encodes the whole context:
        /// <paramref name="first"/> holds each character's first context frame (N * 3K global
        /// positions), <paramref name="target"/> and <paramref name="next"/> N * 3K each,
        /// <paramref name="pastFrames"/> the context frames in all. Then <see cref="Feed"/> the other
        /// <c>pastFrames - 1</c> frames and step: the same frames as <see cref="Start"/>, bit for bit.
        /// </summary>
        public void Begin(TransitionRunner runner, ReadOnlySpan<float> first, ReadOnlySpan<float> target, ReadOnlySpan<float> next, int pastFrames, int length)
        {
            var frames = Size.Count(length, "length", "zoo_transition_begin");
            var past = Size.Count(pastFrames, "pastFrames", "zoo_transition_begin");
            ToModelFrame(ref first, ref target, ref next);
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (float* f = &MemoryMarshal.GetReference(first))
                fixed (float* t = &MemoryMarshal.GetReference(target))
                fixed (float* n = &MemoryMarshal.GetReference(next))
                    s = ZooNative.zoo_transition_begin(rp, cp, f, Size.Of(first.Length), t, Size.Of(target.Length), n, Size.Of(next.Length), past, frames);
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
        }

        /// <summary>Feeds the next context frame of a transition begun with <see cref="Begin"/> (<c>zoo_transition_feed</c>; <paramref name="frame"/> N * 3K global positions).</summary>
        public void Feed(TransitionRunner runner, ReadOnlySpan<float> frame)
        {
            ReadOnlySpan<float> none = default;
            ToModelFrame(ref frame, ref none, ref none);
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (float* f = &MemoryMarshal.GetReference(frame))
                    s = ZooNative.zoo_transition_feed(rp, cp, f, Size.Of(frame.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
        }

        /// <summary>
        /// Position buffers in the model's frame: copied into the scratch array and converted when
        /// the characters were made with an engine frame, left as they are otherwise.
        /// </summary>
        void ToModelFrame(ref ReadOnlySpan<float> a, ref ReadOnlySpan<float> b, ref ReadOnlySpan<float> c)
        {
            if (toModel == null) return;
            var all = Size.Fit(ref floats, a.Length + b.Length + c.Length);
            var sa = new Span<float>(all, 0, a.Length);
            var sb = new Span<float>(all, a.Length, b.Length);
            var sc = new Span<float>(all, a.Length + b.Length, c.Length);
            a.CopyTo(sa);
            b.CopyTo(sb);
            c.CopyTo(sc);
            toModel.PositionsLenient(sa);
            toModel.PositionsLenient(sb);
            toModel.PositionsLenient(sc);
            a = sa;
            b = sb;
            c = sc;
        }

        /// <summary>The next frame of every character's transition as global positions (<c>zoo_transition_step</c>; <paramref name="poses"/> N * 3K).</summary>
        public void Step(TransitionRunner runner, Span<float> poses)
        {
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (float* p = &MemoryMarshal.GetReference(poses))
                    s = ZooNative.zoo_transition_step(rp, cp, p, Size.Of(poses.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
            if (toEngine != null) toEngine.Positions(poses);
        }

        /// <summary>
        /// Starts a transition of <paramref name="length"/> frames from engine poses
        /// (<c>zoo_transition_start_posed</c>): <paramref name="pastRoots"/> holds the same number of
        /// context frames per character (character-major) and <paramref name="pastRotations"/> 4K per
        /// root; the target and next poses one per character (N roots, N * 4K rotations each). The
        /// runtime checks every length.
        /// </summary>
        public void StartPosed(TransitionRunner runner, ReadOnlySpan<ZooRootMotion> pastRoots, ReadOnlySpan<float> pastRotations,
            ReadOnlySpan<ZooRootMotion> targetRoots, ReadOnlySpan<float> targetRotations,
            ReadOnlySpan<ZooRootMotion> nextRoots, ReadOnlySpan<float> nextRotations, int length)
        {
            var frames = Size.Count(length, "length", "zoo_transition_start_posed");
            ToModelPosed(ref pastRoots, ref pastRotations, ref targetRoots, ref targetRotations, ref nextRoots, ref nextRotations);
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (ZooRootMotion* pr = &MemoryMarshal.GetReference(pastRoots))
                fixed (float* pq = &MemoryMarshal.GetReference(pastRotations))
                fixed (ZooRootMotion* tr = &MemoryMarshal.GetReference(targetRoots))
                fixed (float* tq = &MemoryMarshal.GetReference(targetRotations))
                fixed (ZooRootMotion* nr = &MemoryMarshal.GetReference(nextRoots))
                fixed (float* nq = &MemoryMarshal.GetReference(nextRotations))
                    s = ZooNative.zoo_transition_start_posed(rp, cp, pr, Size.Of(pastRoots.Length), pq, Size.Of(pastRotations.Length),
                        tr, Size.Of(targetRoots.Length), tq, Size.Of(targetRotations.Length), nr, Size.Of(nextRoots.Length), nq, Size.Of(nextRotations.Length), frames);
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
        }

        /// <summary>The posed inputs in the model's frame (copies in this object's buffers), when the characters have an engine frame.</summary>
        void ToModelPosed(ref ReadOnlySpan<ZooRootMotion> pastRoots, ref ReadOnlySpan<float> pastRotations,
            ref ReadOnlySpan<ZooRootMotion> targetRoots, ref ReadOnlySpan<float> targetRotations,
            ref ReadOnlySpan<ZooRootMotion> nextRoots, ref ReadOnlySpan<float> nextRotations)
        {
            if (toModel == null) return;
            int np = pastRoots.Length, nt = targetRoots.Length, nn = nextRoots.Length;
            int fp = pastRotations.Length, ft = targetRotations.Length, fn = nextRotations.Length;
            var rs = Size.Fit(ref roots, np + nt + nn);
            var fs = Size.Fit(ref floats, fp + ft + fn);
            var pr = new Span<ZooRootMotion>(rs, 0, np);
            var tr = new Span<ZooRootMotion>(rs, np, nt);
            var nr = new Span<ZooRootMotion>(rs, np + nt, nn);
            var pq = new Span<float>(fs, 0, fp);
            var tq = new Span<float>(fs, fp, ft);
            var nq = new Span<float>(fs, fp + ft, fn);
            pastRoots.CopyTo(pr);
            targetRoots.CopyTo(tr);
            nextRoots.CopyTo(nr);
            pastRotations.CopyTo(pq);
            targetRotations.CopyTo(tq);
            nextRotations.CopyTo(nq);
            toModel.Poses(new Span<ZooRootMotion>(rs, 0, np + nt + nn), Span<float>.Empty);
            toModel.RotationsLenient(pq);
            toModel.RotationsLenient(tq);
            toModel.RotationsLenient(nq);
            pastRoots = pr;
            targetRoots = tr;
            nextRoots = nr;
            pastRotations = pq;
            targetRotations = tq;
            nextRotations = nq;
        }

        /// <summary>
        /// A whole transition of <paramref name="length"/> frames from engine poses in one call
        /// (<c>zoo_transition_generate_posed</c>): the inputs as in <see cref="StartPosed"/>;
        /// <paramref name="outRoots"/> receives N * (length + 1) roots and <paramref name="outRotations"/> 4K
        /// rotations per root (each character's frames, then its target frame).
        /// <paramref name="fallback"/> moves a transition that misses its target by more than the model's
        /// calibrated thresholds towards the interpolation (<c>zoo transition</c>'s default: true);
        /// <paramref name="footLock"/> locks the feet (<c>zoo transition --foot-lock</c>). The frames
        /// <c>zoo transition --in-place</c> writes for the same poses; with both false, those of
        /// <see cref="StartPosed"/> and length + 1 calls of <see cref="StepPosed"/> (up to float rounding for several characters).
        /// </summary>
        public void GeneratePosed(TransitionRunner runner, ReadOnlySpan<ZooRootMotion> pastRoots, ReadOnlySpan<float> pastRotations,
            ReadOnlySpan<ZooRootMotion> targetRoots, ReadOnlySpan<float> targetRotations,
            ReadOnlySpan<ZooRootMotion> nextRoots, ReadOnlySpan<float> nextRotations, int length, bool fallback, bool footLock,
            Span<ZooRootMotion> outRoots, Span<float> outRotations)
        {
            var frames = Size.Count(length, "length", "zoo_transition_generate_posed");
            ToModelPosed(ref pastRoots, ref pastRotations, ref targetRoots, ref targetRotations, ref nextRoots, ref nextRotations);
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (ZooRootMotion* pr = &MemoryMarshal.GetReference(pastRoots))
                fixed (float* pq = &MemoryMarshal.GetReference(pastRotations))
                fixed (ZooRootMotion* tr = &MemoryMarshal.GetReference(targetRoots))
                fixed (float* tq = &MemoryMarshal.GetReference(targetRotations))
                fixed (ZooRootMotion* nr = &MemoryMarshal.GetReference(nextRoots))
                fixed (float* nq = &MemoryMarshal.GetReference(nextRotations))
                fixed (ZooRootMotion* o = &MemoryMarshal.GetReference(outRoots))
                fixed (float* q = &MemoryMarshal.GetReference(outRotations))
                    s = ZooNative.zoo_transition_generate_posed(rp, cp, pr, Size.Of(pastRoots.Length), pq, Size.Of(pastRotations.Length),
                        tr, Size.Of(targetRoots.Length), tq, Size.Of(targetRotations.Length), nr, Size.Of(nextRoots.Length), nq, Size.Of(nextRotations.Length),
                        frames, (byte)(fallback ? 1 : 0), (byte)(footLock ? 1 : 0), o, Size.Of(outRoots.Length), q, Size.Of(outRotations.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
            if (toEngine != null) toEngine.Poses(outRoots, outRotations);
        }

        /// <summary>The next frame of every character's transition as engine poses (<c>zoo_transition_step_posed</c>): <paramref name="roots"/> N, <paramref name="rotations"/> N * 4K local rotations.</summary>
        public void StepPosed(TransitionRunner runner, Span<ZooRootMotion> roots, Span<float> rotations)
        {
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooTransitionRunner*)Enter(runner, ref r);
                var cp = (Native.ZooTransitionCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (ZooRootMotion* o = &MemoryMarshal.GetReference(roots))
                fixed (float* q = &MemoryMarshal.GetReference(rotations))
                    s = ZooNative.zoo_transition_step_posed(rp, cp, o, Size.Of(roots.Length), q, Size.Of(rotations.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
            if (toEngine != null) toEngine.Poses(roots, rotations);
        }

        /// <summary>Sets the ground under character <paramref name="index"/> (<c>zoo_transition_set_heightmap</c>; heights, cell and origin in model units and axes); empty heights remove it.</summary>
        public void SetHeightmap(int index, int cols, int rows, float cell, float originX, float originZ, ReadOnlySpan<float> heights)
        {
            var nc = Size.Count(cols, "cols", "zoo_transition_set_heightmap");
            var nr = Size.Count(rows, "rows", "zoo_transition_set_heightmap");
            bool c = false;
            try
            {
                ZooStatus s;
                fixed (float* h = &MemoryMarshal.GetReference(heights))
                    s = ZooNative.zoo_transition_set_heightmap((Native.ZooTransitionCharacters*)Enter(this, ref c), Size.Of(index), nc, nr,
                        cell, originX, originZ, h, Size.Of(heights.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, c); }
        }

        /// <summary>Frames character <paramref name="index"/>'s transition still returns (<c>zoo_transition_frames_left</c>; 0 once it returned its target frame).</summary>
        public int FramesLeft(int index)
        {
            bool c = false;
            try
            {
                UIntPtr left = UIntPtr.Zero;
                Errors.Check(ZooNative.zoo_transition_frames_left((Native.ZooTransitionCharacters*)Enter(this, ref c), Size.Of(index), &left), this);
                return Size.Int(left);
            }
            finally { Exit(this, c); }
        }

        /// <summary>How far the network's own target frame lay from the requested target (<c>zoo_transition_target_miss</c>, model units); false before stepping reaches the blend window.</summary>
        public bool TryGetTargetMiss(int index, out float mean, out float max)
        {
            bool c = false;
            try
            {
                float a = 0f, b = 0f;
                var s = ZooNative.zoo_transition_target_miss((Native.ZooTransitionCharacters*)Enter(this, ref c), Size.Of(index), &a, &b);
                mean = a;
                max = b;
                if (s == ZooStatus.NotAvailable) return false;
                Errors.Check(s, this);
                return true;
            }
            finally { Exit(this, c); }
        }
    }
}
