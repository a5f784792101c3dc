// Synthesis (RNN-GMM) and its speed / facing control: zoo_synthesis_runner_*,
// zoo_synthesis_characters_*, zoo_synthesis_start, zoo_synthesis_step, zoo_control_*.
using System;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>Scratch space for stepping synthesis characters, on one thread at a time (<c>ZooSynthesisRunner</c>).</summary>
    public sealed unsafe class SynthesisRunner : ZooObject
    {
        SynthesisRunner(ZooSafeHandle handle) : base(handle) { }

        /// <summary>A runner for up to <paramref name="maxBatch"/> characters per step (<c>zoo_synthesis_runner_new</c>; 1 to <see cref="ZooNative.ZOO_MAX_BATCH"/>; a larger batch is refused at its step).</summary>
        public SynthesisRunner(Model model, int maxBatch) : this(Create(model, maxBatch)) { }

        static ZooSafeHandle Create(Model model, int maxBatch)
        {
            var batch = Size.Count(maxBatch, "maxBatch", "zoo_synthesis_runner_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_synthesis_runner_new((Native.ZooModel*)Enter(model, ref e), batch, (Native.ZooSynthesisRunner**)&p), model);
                return Wrap(HandleKind.SynthesisRunner, p);
            }
            finally { Exit(model, e); }
        }
    }

    /// <summary>
    /// The generators of a batch of characters, on one thread at a time
    /// (<c>ZooSynthesisCharacters</c>). Start frames and placements are in the model's units and
    /// axes (see <see cref="PoseConversion"/> to place characters from engine coordinates); the
    /// generated poses are in the engine frame given at creation, else the model's. Steps allocate nothing.
    /// </summary>
    public sealed unsafe class SynthesisCharacters : ZooObject
    {
        readonly int count;
        readonly PoseConversion toEngine;

        SynthesisCharacters(ZooSafeHandle handle, Model model, int count, ZooCoordinateFrame? engine) : base(handle)
        {
            this.count = count;
            if (engine.HasValue) toEngine = new PoseConversion(model.Frame, engine.Value);
        }

        /// <summary>One character per seed (<c>zoo_synthesis_characters_new</c>).</summary>
        public SynthesisCharacters(Model model, ReadOnlySpan<ulong> seeds, ZooCoordinateFrame? engine = null) : this(Create(model, seeds), model, seeds.Length, engine) { }

        static ZooSafeHandle Create(Model model, ReadOnlySpan<ulong> seeds)
        {
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                ZooStatus s;
                fixed (ulong* sp = &MemoryMarshal.GetReference(seeds))
                    s = ZooNative.zoo_synthesis_characters_new((Native.ZooModel*)Enter(model, ref e), sp, Size.Of(seeds.Length), (Native.ZooSynthesisCharacters**)&p);
                Errors.Check(s, model);
                return Wrap(HandleKind.SynthesisCharacters, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>Characters N in the batch.</summary>
        public int Count { get { ThrowIfDisposed("Count"); return count; } }

        /// <summary>Starts every character (<c>zoo_synthesis_start</c>): <paramref name="frames"/> N * D feature frames, <paramref name="placements"/> <c>x z yaw</c> per character (model units and axes).</summary>
        public void Start(ReadOnlySpan<float> frames, ReadOnlySpan<float> placements)
        {
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (float* f = &MemoryMarshal.GetReference(frames))
                fixed (float* p = &MemoryMarshal.GetReference(placements))
                    s = ZooNative.zoo_synthesis_start((Native.ZooSynthesisCharacters*)Enter(this, ref e), f, Size.Of(frames.Length), p, Size.Of(placements.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }

        /// <summary>Generates every character's next frame in one graph run (<c>zoo_synthesis_step</c>): N roots, N * 4K rotations, N * 2 contact bytes.</summary>
        public void Step(SynthesisRunner runner, float temperature, Span<ZooRootMotion> roots, Span<float> rotations, Span<byte> contacts)
        {
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooSynthesisRunner*)Enter(runner, ref r);
                var cp = (Native.ZooSynthesisCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (ZooRootMotion* o = &MemoryMarshal.GetReference(roots))
                fixed (float* q = &MemoryMarshal.GetReference(rotations))
                fixed (byte* b = &MemoryMarshal.GetReference(contacts))
                    s = ZooNative.zoo_synthesis_step(rp, cp, temperature, o, Size.Of(roots.Length), q, Size.Of(rotations.Length), b, Size.Of(contacts.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
            if (toEngine != null) toEngine.Poses(roots, rotations);
        }
    }

    /// <summary>How controlled characters plan (<c>ZooControlSettings</c>); <see cref="Default"/> is the runtime's.</summary>
    public sealed class ControlSettings
    {
        /// <summary>Frames per planned batch (also the control's latency in frames); at least 1.</summary>
        public int Batch;
        /// <summary>Standard deviation of the speed term, model units per second; positive.</summary>
        public float SigmaSpeed;
        /// <summary>Standard deviation of the facing term, radians; positive.</summary>
        public float SigmaHeading;
        /// <summary>Scale of the mixture's standard deviations when drawing (1: the model's, 0: its means).</summary>
        public float Temperature;
        /// <summary>Offsets of a candidate's forward step, in data standard deviations; null: the defaults.</summary>
        public float[] SpeedOffsets;
        /// <summary>Offsets of a candidate's turn, in data standard deviations; null: the defaults.</summary>
        public float[] TurnOffsets;

        /// <summary>The runtime's defaults (<c>zoo_control_settings_default</c>).</summary>
        public static unsafe ControlSettings Default()
        {
            Model.CheckLibrary();
            var s = default(ZooControlSettings);
            Errors.Check(ZooNative.zoo_control_settings_default(&s));
            return new ControlSettings { Batch = Size.Int(s.Batch), SigmaSpeed = s.SigmaSpeed, SigmaHeading = s.SigmaHeading, Temperature = s.Temperature };
        }
    }

    /// <summary>Scratch space for stepping controlled characters, on one thread at a time (<c>ZooControlRunner</c>).</summary>
    public sealed unsafe class ControlRunner : ZooObject
    {
        ControlRunner(ZooSafeHandle handle) : base(handle) { }

        /// <summary>A runner for up to <paramref name="maxBatch"/> controlled characters of <paramref name="model"/> per step (<c>zoo_control_runner_new</c>; 1 to <see cref="ZooNative.ZOO_MAX_BATCH"/>; a larger batch is refused at its step).</summary>
        public ControlRunner(Model model, int maxBatch) : this(Create(model, maxBatch)) { }

        static ZooSafeHandle Create(Model model, int maxBatch)
        {
            var batch = Size.Count(maxBatch, "maxBatch", "zoo_control_runner_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_control_runner_new((Native.ZooModel*)Enter(model, ref e), batch, (Native.ZooControlRunner**)&p), model);
                return Wrap(HandleKind.ControlRunner, p);
            }
            finally { Exit(model, e); }
        }
    }

    /// <summary>
    /// A batch of characters steered by speed and facing (<c>ZooControlCharacters</c>), on one
    /// thread at a time. Seed frames, placements and controls are in the model's units and axes;
    /// the poses in the engine frame given at creation, else the model's. Steps allocate nothing.
    /// </summary>
    public sealed unsafe class ControlCharacters : ZooObject
    {
        readonly int count;
        readonly PoseConversion toEngine;

        ControlCharacters(ZooSafeHandle handle, Model model, int count, ZooCoordinateFrame? engine) : base(handle)
        {
            this.count = count;
            if (engine.HasValue) toEngine = new PoseConversion(model.Frame, engine.Value);
        }

        /// <summary>One character per seed planning with <paramref name="settings"/> (null: the defaults; <c>zoo_control_characters_new</c>).</summary>
        public ControlCharacters(Model model, ReadOnlySpan<ulong> seeds, ControlSettings settings = null, ZooCoordinateFrame? engine = null)
            : this(Create(model, seeds, settings), model, seeds.Length, engine) { }

        static ZooSafeHandle Create(Model model, ReadOnlySpan<ulong> seeds, ControlSettings settings)
        {
            var planned = settings == null ? UIntPtr.Zero : Size.Count(settings.Batch, "settings.Batch", "zoo_control_characters_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                ZooStatus s;
                var m = (Native.ZooModel*)Enter(model, ref e);
                fixed (ulong* sp = &MemoryMarshal.GetReference(seeds))
                {
                    if (settings == null)
                    {
                        s = ZooNative.zoo_control_characters_new(m, sp, Size.Of(seeds.Length), null, (Native.ZooControlCharacters**)&p);
                    }
                    else
                    {
                        fixed (float* so = settings.SpeedOffsets)
                        fixed (float* to = settings.TurnOffsets)
                        {
                            var c = new ZooControlSettings
                            {
                                Batch = planned,
                                SigmaSpeed = settings.SigmaSpeed,
                                SigmaHeading = settings.SigmaHeading,
                                Temperature = settings.Temperature,
                                SpeedOffsets = so,
                                SpeedOffsetsLen = Size.Of(settings.SpeedOffsets == null ? 0 : settings.SpeedOffsets.Length),
                                TurnOffsets = to,
                                TurnOffsetsLen = Size.Of(settings.TurnOffsets == null ? 0 : settings.TurnOffsets.Length),
                            };
                            s = ZooNative.zoo_control_characters_new(m, sp, Size.Of(seeds.Length), &c, (Native.ZooControlCharacters**)&p);
                        }
                    }
                }
                Errors.Check(s, model);
                return Wrap(HandleKind.ControlCharacters, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>Characters N in the batch.</summary>
        public int Count { get { ThrowIfDisposed("Count"); return count; } }

        /// <summary>Starts every character from its seed frames (<c>zoo_control_start</c>): N * F * D floats, <c>x z yaw</c> placements per character.</summary>
        public void Start(ReadOnlySpan<float> frames, ReadOnlySpan<float> placements)
        {
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (float* f = &MemoryMarshal.GetReference(frames))
                fixed (float* p = &MemoryMarshal.GetReference(placements))
                    s = ZooNative.zoo_control_start((Native.ZooControlCharacters*)Enter(this, ref e), f, Size.Of(frames.Length), p, Size.Of(placements.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }

        /// <summary>Plays every character's next frame under its control (<c>zoo_control_step</c>): one control per character; N roots, N * 4K rotations, N * 2 contacts out.</summary>
        public void Step(ControlRunner runner, ReadOnlySpan<ZooControl> controls, Span<ZooRootMotion> roots, Span<float> rotations, Span<byte> contacts)
        {
            bool r = false, c = false;
            try
            {
                var rp = (Native.ZooControlRunner*)Enter(runner, ref r);
                var cp = (Native.ZooControlCharacters*)Enter(this, ref c);
                ZooStatus s;
                fixed (ZooControl* z = &MemoryMarshal.GetReference(controls))
                fixed (ZooRootMotion* o = &MemoryMarshal.GetReference(roots))
                fixed (float* q = &MemoryMarshal.GetReference(rotations))
                fixed (byte* b = &MemoryMarshal.GetReference(contacts))
                    s = ZooNative.zoo_control_step(rp, cp, z, Size.Of(controls.Length), o, Size.Of(roots.Length), q, Size.Of(rotations.Length), b, Size.Of(contacts.Length));
                Errors.Check(s, runner, this);
            }
            finally { Exit(runner, r); Exit(this, c); }
            if (toEngine != null) toEngine.Poses(roots, rotations);
        }
    }
}
