// The model: zoo_model_load, zoo_model_load_memory, zoo_model_task, zoo_model_info, zoo_model_skeleton,
// zoo_model_joint_name, each task's info, and the calls on a model itself (zoo_transition_terrain,
// zoo_stitch_set_window, zoo_stitch_refine, zoo_stitch_refine_at_seams, zoo_synthesis_set_refine, zoo_synthesis_mean_frame).
using System;
using System.Runtime.InteropServices;
using System.Text;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// A model exported by <c>zoo export --onnx</c>, of any task (<see cref="Task"/>). Thread-safe:
    /// share one model between threads and make a runner and characters per thread from it.
    /// Runners, characters and streams keep what they need, so the model may be disposed before them.
    /// </summary>
    public sealed unsafe class Model : ZooObject
    {
        readonly ZooModelInfo info;

        Model(ZooSafeHandle handle, ZooModelInfo info) : base(handle)
        {
            this.info = info;
        }

        /// <summary>
        /// Loads a model file (<c>zoo_model_load</c>); the runtime refuses a file that is not an
        /// exported model with a <see cref="ZooException"/> naming the fix. Checks first that the
        /// native library is there and has the C ABI version of these bindings.
        /// </summary>
        public static Model Load(string path)
        {
            CheckLibrary();
            var utf8 = path == null ? null : Encoding.UTF8.GetBytes(path + "\0");
            IntPtr p = IntPtr.Zero;
            ZooStatus s;
            fixed (byte* b = utf8) s = ZooNative.zoo_model_load(b, (Native.ZooModel**)&p);
            Errors.Check(s);
            return Loaded(p);
        }

        /// <summary>
        /// Loads a model from the bytes of its file (<c>zoo_model_load_memory</c>), with the same checks and
        /// the same model as <see cref="Load"/> of that file: for a file that is not on the file system, such
        /// as one in an Android APK's <c>StreamingAssets</c> (read it with <c>UnityWebRequest</c>), an asset
        /// bundle or a <c>TextAsset</c>'s <c>bytes</c> (Documentation~/zoo.md, Loading a model). The library
        /// keeps no reference to <paramref name="bytes"/>. A <c>zoo export --portable</c> file, whose weights
        /// are in companion files, loads from its files only.
        /// </summary>
        public static Model FromBytes(byte[] bytes)
        {
            CheckLibrary();
            IntPtr p = IntPtr.Zero;
            ZooStatus s;
            // An empty array is passed as a valid pointer and 0 (the runtime refuses it as no model), not as NULL.
            byte none = 0;
            fixed (byte* b = bytes)
                s = ZooNative.zoo_model_load_memory(bytes == null ? null : bytes.Length == 0 ? &none : b, bytes == null ? UIntPtr.Zero : (UIntPtr)(uint)bytes.Length, (Native.ZooModel**)&p);
            Errors.Check(s);
            return Loaded(p);
        }

        /// <summary>The wrapper of a model the runtime just loaded into <paramref name="p"/>, with its info.</summary>
        static Model Loaded(IntPtr p)
        {
            var handle = Wrap(HandleKind.Model, p);
            var info = default(ZooModelInfo);
            var s = ZooNative.zoo_model_info((Native.ZooModel*)p, &info);
            if (s != ZooStatus.Ok)
            {
                var e = Errors.Fail(s);
                handle.Dispose();
                throw e;
            }
            return new Model(handle, info);
        }

        /// <summary>Throws when the native library is missing or of another C ABI version than these bindings (<see cref="Library.Check"/>).</summary>
        public static void CheckLibrary()
        {
            Library.Check();
        }

        /// <summary>What every model is (<c>zoo_model_info</c>, read at load). Like every member, throws <see cref="ZooDisposedException"/> once the model is disposed.</summary>
        public ZooModelInfo Info { get { ThrowIfDisposed("Info"); return info; } }

        /// <summary>The model's task: which wrappers run it.</summary>
        public ZooTask Task { get { ThrowIfDisposed("Task"); return info.Task; } }

        /// <summary>Joints K of the model's skeleton: a pose is a root and 4K rotation values.</summary>
        public int Joints { get { ThrowIfDisposed("Joints"); return info.JointCount; } }

        /// <summary>Frames per second of the model's motion.</summary>
        public float Fps { get { ThrowIfDisposed("Fps"); return info.Fps; } }

        /// <summary>The model's units and axes.</summary>
        public ZooCoordinateFrame Frame { get { ThrowIfDisposed("Frame"); return info.Frame; } }

        /// <summary>The conversion of this model's poses to an engine's frame (e.g. <see cref="ZooCoordinateFrame.Unity"/>).</summary>
        public PoseConversion ToEngine(ZooCoordinateFrame engine)
        {
            ThrowIfDisposed("ToEngine");
            return new PoseConversion(info.Frame, engine);
        }

        /// <summary>The task as the runtime reports it now (<c>zoo_model_task</c>).</summary>
        public ZooTask QueryTask()
        {
            bool e = false;
            try
            {
                var m = (Native.ZooModel*)Enter(this, ref e);
                var task = ZooNative.zoo_model_task(m);
                if (task == ZooTask.None) throw Errors.Fail(ZooStatus.NullPointer, this);
                return task;
            }
            finally { Exit(this, e); }
        }

        /// <summary>The skeleton (<c>zoo_model_skeleton</c>): <paramref name="parents"/> K parent indices (-1 for the root), <paramref name="offsets"/> 3K rest offsets, model units (converted by <paramref name="to"/> when given).</summary>
        public void GetSkeleton(Span<int> parents, Span<float> offsets, PoseConversion to = null)
        {
            bool e = false;
            try
            {
                var m = (Native.ZooModel*)Enter(this, ref e);
                ZooStatus s;
                fixed (int* p = &MemoryMarshal.GetReference(parents))
                fixed (float* o = &MemoryMarshal.GetReference(offsets))
                    s = ZooNative.zoo_model_skeleton(m, p, Size.Of(parents.Length), o, Size.Of(offsets.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
            if (to != null) to.Positions(offsets);
        }

        /// <summary>The name of joint <paramref name="joint"/> (<c>zoo_model_joint_name</c>; allocates the string).</summary>
        public string JointName(int joint)
        {
            bool e = false;
            try
            {
                var m = (Native.ZooModel*)Enter(this, ref e);
                UIntPtr length = UIntPtr.Zero;
                Errors.Check(ZooNative.zoo_model_joint_name(m, Size.Of(joint), null, UIntPtr.Zero, &length), this);
                var bytes = new byte[Size.Int(length) + 1];
                fixed (byte* b = bytes) Errors.Check(ZooNative.zoo_model_joint_name(m, Size.Of(joint), b, Size.Of(bytes.Length), &length), this);
                return Encoding.UTF8.GetString(bytes, 0, Size.Int(length));
            }
            finally { Exit(this, e); }
        }

        /// <summary>Every joint's name, in the order of every pose (allocates).</summary>
        public string[] JointNames()
        {
            var names = new string[Joints];
            for (int j = 0; j < names.Length; j++) names[j] = JointName(j);
            return names;
        }

        /// <summary>What a transition model expects (<c>zoo_transition_info</c>); another task's model is refused.</summary>
        public ZooTransitionInfo TransitionInfo
        {
            get
            {
                bool e = false;
                try
                {
                    var i = default(ZooTransitionInfo);
                    Errors.Check(ZooNative.zoo_transition_info((Native.ZooModel*)Enter(this, ref e), &i), this);
                    return i;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>The terrain patch of a terrain-aware transition model (<c>zoo_transition_terrain</c>); false for a flat-ground model.</summary>
        public bool TryGetTerrain(out int side, out float extent)
        {
            bool e = false;
            try
            {
                UIntPtr s = UIntPtr.Zero;
                float x = 0f;
                var status = ZooNative.zoo_transition_terrain((Native.ZooModel*)Enter(this, ref e), &s, &x);
                side = Size.Int(s);
                extent = x;
                if (status == ZooStatus.NotAvailable) return false;
                Errors.Check(status, this);
                return true;
            }
            finally { Exit(this, e); }
        }

        /// <summary>What a keyframes model expects (<c>zoo_keyframes_info</c>).</summary>
        public ZooKeyframesInfo KeyframesInfo
        {
            get
            {
                bool e = false;
                try
                {
                    var i = default(ZooKeyframesInfo);
                    Errors.Check(ZooNative.zoo_keyframes_info((Native.ZooModel*)Enter(this, ref e), &i), this);
                    return i;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>What a stitching model expects (<c>zoo_stitch_info</c>).</summary>
        public ZooStitchInfo StitchInfo
        {
            get
            {
                bool e = false;
                try
                {
                    var i = default(ZooStitchInfo);
                    Errors.Check(ZooNative.zoo_stitch_info((Native.ZooModel*)Enter(this, ref e), &i), this);
                    return i;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>Whether a stitching model was trained on clips inertialized at their seams (<c>zoo_stitch_pre_blend</c>; <c>zoo train rmr</c>'s default): refine its sequences with <see cref="StitchRefineAtSeams"/> and mark a stream's seams, as <c>zoo stitch</c> does.</summary>
        public bool StitchPreBlend
        {
            get
            {
                bool e = false;
                try
                {
                    bool b = false;
                    Errors.Check(ZooNative.zoo_stitch_pre_blend((Native.ZooModel*)Enter(this, ref e), &b), this);
                    return b;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>What a synthesis model expects (<c>zoo_synthesis_info</c>).</summary>
        public ZooSynthesisInfo SynthesisInfo
        {
            get
            {
                bool e = false;
                try
                {
                    var i = default(ZooSynthesisInfo);
                    Errors.Check(ZooNative.zoo_synthesis_info((Native.ZooModel*)Enter(this, ref e), &i), this);
                    return i;
                }
                finally { Exit(this, e); }
            }
        }

        /// <summary>Plans a stitching model for another window and stride (<c>zoo_stitch_set_window</c>). Not thread-safe: no other thread may use the model meanwhile, and its streams must be disposed first.</summary>
        public void SetStitchWindow(int window, int stride)
        {
            var w = Size.Count(window, "window", "zoo_stitch_set_window");
            var st = Size.Count(stride, "stride", "zoo_stitch_set_window");
            bool e = false;
            try { Errors.Check(ZooNative.zoo_stitch_set_window((Native.ZooModel*)Enter(this, ref e), w, st), this); }
            finally { Exit(this, e); }
        }

        /// <summary>Switches the seam guard of <see cref="StitchRefineAtSeams"/> on (the default, as <c>zoo stitch</c>) or off (<c>zoo_stitch_set_seam_guard</c>). Not thread-safe: no other thread may use the model meanwhile, and its streams must be disposed first.</summary>
        public void SetStitchSeamGuard(bool on)
        {
            bool e = false;
            try { Errors.Check(ZooNative.zoo_stitch_set_seam_guard((Native.ZooModel*)Enter(this, ref e), on), this); }
            finally { Exit(this, e); }
        }

        /// <summary>
        /// The seams' reach of <see cref="StitchRefineAtSeams"/> and of the streams made from now on
        /// (<c>zoo_stitch_set_seam_reach</c>): frames <paramref name="frames"/> or more from every seam are
        /// left as given; 0 refines the whole sequence. Default: the model's window, as <c>zoo stitch</c>.
        /// Not thread-safe; streams made from the model must be disposed first.
        /// </summary>
        public void SetStitchSeamReach(int frames)
        {
            if (frames < 0) throw new ArgumentOutOfRangeException(nameof(frames), frames, "the seams' reach is a number of frames, 0 or more (0: refine everywhere)");
            bool e = false;
            try { Errors.Check(ZooNative.zoo_stitch_set_seam_reach((Native.ZooModel*)Enter(this, ref e), (UIntPtr)(ulong)frames), this); }
            finally { Exit(this, e); }
        }

        /// <summary>Whether synthesis runners and characters made from now on refine each frame (<c>zoo_synthesis_set_refine</c>). Not thread-safe.</summary>
        public void SetSynthesisRefine(bool refine)
        {
            bool e = false;
            try { Errors.Check(ZooNative.zoo_synthesis_set_refine((Native.ZooModel*)Enter(this, ref e), refine), this); }
            finally { Exit(this, e); }
        }

        /// <summary>The training data's mean feature frame, a neutral synthesis start frame (<c>zoo_synthesis_mean_frame</c>; D floats, model units).</summary>
        public void SynthesisMeanFrame(Span<float> frame)
        {
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (float* f = &MemoryMarshal.GetReference(frame))
                    s = ZooNative.zoo_synthesis_mean_frame((Native.ZooModel*)Enter(this, ref e), f, Size.Of(frame.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }

        /// <summary>
        /// Refines a whole aligned sequence (<c>zoo_stitch_refine</c>): <paramref name="roots"/> one
        /// root per frame, <paramref name="rotations"/> 4K per frame, into the output buffers of the
        /// same sizes and 4 contact bytes per frame. With <paramref name="engine"/> the poses in and
        /// out are in that frame (the input is copied and converted: this call allocates). Thread-safe.
        /// </summary>
        public void StitchRefine(ReadOnlySpan<ZooRootMotion> roots, ReadOnlySpan<float> rotations, bool placeAnkles, bool lockFeet,
            Span<ZooRootMotion> outRoots, Span<float> outRotations, Span<byte> contacts, ZooCoordinateFrame? engine = null)
            => Refine(roots, rotations, null, placeAnkles, lockFeet, outRoots, outRotations, contacts, engine);

        /// <summary>
        /// <see cref="StitchRefine"/> of the sequence inertialized at <paramref name="seams"/> first
        /// (<c>zoo_stitch_refine_at_seams</c>; the frames where a clip starts): the jump at each seam
        /// decays over the model's blend frames before the refiner runs (<c>zoo stitch --pre-blend</c>).
        /// Thread-safe.
        /// </summary>
        public void StitchRefineAtSeams(ReadOnlySpan<ZooRootMotion> roots, ReadOnlySpan<float> rotations, ReadOnlySpan<int> seams,
            bool placeAnkles, bool lockFeet, Span<ZooRootMotion> outRoots, Span<float> outRotations, Span<byte> contacts,
            ZooCoordinateFrame? engine = null)
        {
            var at = new UIntPtr[seams.Length];
            for (int i = 0; i < seams.Length; i++) at[i] = Size.Of(seams[i]);
            Refine(roots, rotations, at, placeAnkles, lockFeet, outRoots, outRotations, contacts, engine);
        }

        void Refine(ReadOnlySpan<ZooRootMotion> roots, ReadOnlySpan<float> rotations, UIntPtr[] seams, bool placeAnkles, bool lockFeet,
            Span<ZooRootMotion> outRoots, Span<float> outRotations, Span<byte> contacts, ZooCoordinateFrame? engine)
        {
            if (engine.HasValue)
            {
                ThrowIfDisposed("StitchRefine");
                var toModel = new PoseConversion(engine.Value, info.Frame);
                var r = roots.ToArray();
                var q = rotations.ToArray();
                toModel.Poses(r, Span<float>.Empty);
                toModel.RotationsLenient(q);
                roots = r;
                rotations = q;
            }
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (ZooRootMotion* r = &MemoryMarshal.GetReference(roots))
                fixed (float* q = &MemoryMarshal.GetReference(rotations))
                fixed (ZooRootMotion* outR = &MemoryMarshal.GetReference(outRoots))
                fixed (float* outQ = &MemoryMarshal.GetReference(outRotations))
                fixed (byte* c = &MemoryMarshal.GetReference(contacts))
                fixed (UIntPtr* at = seams)
                    s = seams == null
                        ? ZooNative.zoo_stitch_refine((Native.ZooModel*)Enter(this, ref e), r, Size.Of(roots.Length), q, Size.Of(rotations.Length),
                            placeAnkles, lockFeet, outR, Size.Of(outRoots.Length), outQ, Size.Of(outRotations.Length), c, Size.Of(contacts.Length))
                        : ZooNative.zoo_stitch_refine_at_seams((Native.ZooModel*)Enter(this, ref e), r, Size.Of(roots.Length), q, Size.Of(rotations.Length),
                            at, Size.Of(seams.Length), placeAnkles, lockFeet, outR, Size.Of(outRoots.Length), outQ, Size.Of(outRotations.Length), c,
                            Size.Of(contacts.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
            if (engine.HasValue) new PoseConversion(info.Frame, engine.Value).Poses(outRoots, outRotations);
        }
    }
}
