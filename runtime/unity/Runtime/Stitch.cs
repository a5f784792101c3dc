// Stitching streams (RMR): zoo_stitch_stream_*, seams marked by zoo_stitch_stream_mark_seam (the whole
// sequence is Model.StitchRefine / StitchRefineAtSeams).
using System;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// A stitching stream, on one thread at a time (<c>ZooStitchStream</c>): push the aligned
    /// motion one pose per frame, pop each refined pose <see cref="Latency"/> frames later. Made
    /// with an engine frame, poses in and out are in that frame. Push and pop allocate nothing.
    /// </summary>
    public sealed unsafe class StitchStream : ZooObject
    {
        int latency;
        readonly PoseConversion toModel;
        readonly PoseConversion toEngine;
        float[] rotations;

        StitchStream(ZooSafeHandle handle, Model model, ZooCoordinateFrame? engine) : base(handle)
        {
            latency = model.StitchInfo.LatencyFrames;
            if (engine.HasValue)
            {
                toModel = new PoseConversion(engine.Value, model.Frame);
                toEngine = toModel.Inverse;
            }
        }

        /// <summary>A stream over <paramref name="model"/> (<c>zoo_stitch_stream_new</c>); poses in <paramref name="engine"/>'s frame when given.</summary>
        public StitchStream(Model model, ZooCoordinateFrame? engine = null) : this(Create(model), model, engine) { }

        static ZooSafeHandle Create(Model model)
        {
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_stitch_stream_new((Native.ZooModel*)Enter(model, ref e), (Native.ZooStitchStream**)&p), model);
                return Wrap(HandleKind.StitchStream, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>
        /// Frames between pushing a pose and popping it refined (<c>zoo_stitch_stream_latency</c>): the window,
        /// the lookahead of the seam guard and the foot lock, and the frames they release at once, less one
        /// (<see cref="ZooStitchInfo.Latency"/>); the window alone without them.
        /// </summary>
        public int Latency { get { ThrowIfDisposed("Latency"); return latency; } }

        /// <summary>
        /// Sets what follows the refiner, before the first push (<c>zoo_stitch_stream_set_cleanup</c>): the ankle IK
        /// and the foot lock of <c>zoo stitch</c> (both on by default); the seam guard follows the model's
        /// (<see cref="Model.SetStitchSeamGuard"/>). Updates <see cref="Latency"/>.
        /// </summary>
        public void SetCleanup(bool placeAnkles, bool lockFeet)
        {
            bool e = false;
            try
            {
                var s = (Native.ZooStitchStream*)Enter(this, ref e);
                Errors.Check(ZooNative.zoo_stitch_stream_set_cleanup(s, placeAnkles, lockFeet), this);
                UIntPtr n = UIntPtr.Zero;
                Errors.Check(ZooNative.zoo_stitch_stream_latency(s, &n), this);
                latency = (int)n.ToUInt64();
            }
            finally { Exit(this, e); }
        }

        /// <summary>Pushes the next pose of the aligned motion (<c>zoo_stitch_stream_push</c>): a root and 4K rotations.</summary>
        public void Push(ZooRootMotion root, ReadOnlySpan<float> poseRotations)
        {
            if (toModel != null)
            {
                var q = new Span<float>(Size.Fit(ref rotations, poseRotations.Length), 0, poseRotations.Length);
                poseRotations.CopyTo(q);
                toModel.Root(ref root);
                toModel.RotationsLenient(q);
                poseRotations = q;
            }
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (float* q = &MemoryMarshal.GetReference(poseRotations))
                    s = ZooNative.zoo_stitch_stream_push((Native.ZooStitchStream*)Enter(this, ref e), &root, q, Size.Of(poseRotations.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }

        /// <summary>Whether the next refined pose can be popped (<c>zoo_stitch_stream_ready</c>).</summary>
        public bool Ready
        {
            get
            {
                bool e = false;
                try
                {
                    bool ready = false;
                    Errors.Check(ZooNative.zoo_stitch_stream_ready((Native.ZooStitchStream*)Enter(this, ref e), &ready), this);
                    return ready;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>Pops the next refined pose and its 4 contact bytes (<c>zoo_stitch_stream_pop</c>); false, writing nothing, when it is not ready yet.</summary>
        public bool TryPop(ref ZooRootMotion root, Span<float> poseRotations, Span<byte> contacts)
        {
            bool e = false;
            ZooStatus s;
            try
            {
                fixed (ZooRootMotion* r = &root)
                fixed (float* q = &MemoryMarshal.GetReference(poseRotations))
                fixed (byte* c = &MemoryMarshal.GetReference(contacts))
                    s = ZooNative.zoo_stitch_stream_pop((Native.ZooStitchStream*)Enter(this, ref e), r, q, Size.Of(poseRotations.Length), c, Size.Of(contacts.Length));
                if (s == ZooStatus.NotAvailable) return false;
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
            if (toEngine != null)
            {
                toEngine.Root(ref root);
                toEngine.Poses(Span<ZooRootMotion>.Empty, poseRotations);
            }
            return true;
        }

        /// <summary>
        /// Marks the next pushed pose as the first of a new clip (<c>zoo_stitch_stream_mark_seam</c>): the stream
        /// inertializes the seam before refining and guards it, as <see cref="Model.StitchRefineAtSeams"/> does.
        /// </summary>
        public void MarkSeam()
        {
            bool e = false;
            try { Errors.Check(ZooNative.zoo_stitch_stream_mark_seam((Native.ZooStitchStream*)Enter(this, ref e)), this); }
            finally { Exit(this, e); }
        }

        /// <summary>Ends the motion (<c>zoo_stitch_stream_finish</c>): every remaining pose becomes ready to pop.</summary>
        public void Finish()
        {
            bool e = false;
            try { Errors.Check(ZooNative.zoo_stitch_stream_finish((Native.ZooStitchStream*)Enter(this, ref e)), this); }
            finally { Exit(this, e); }
        }
    }
}
