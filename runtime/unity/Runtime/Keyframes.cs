// Keyframe completion (ARNN): zoo_keyframes_runner_*, zoo_keyframes_complete(_batch).
using System;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// Scratch space for completing keys of up to a batch of characters per call, on one thread at
    /// a time (<c>ZooKeyframesRunner</c>). Keys and completed frames are D values per pose in the
    /// model's units (<see cref="Model.KeyframesInfo"/>'s <c>FrameValues</c>; the lamp's 6), not engine poses.
    /// </summary>
    public sealed unsafe class KeyframesRunner : ZooObject
    {
        UIntPtr[] frames;
        UIntPtr[] counts;

        KeyframesRunner(ZooSafeHandle handle) : base(handle) { }

        /// <summary>A runner for batches of up to <paramref name="maxBatch"/> characters (<c>zoo_keyframes_runner_new</c>; 1 to <see cref="ZooNative.ZOO_MAX_BATCH"/>).</summary>
        public KeyframesRunner(Model model, int maxBatch) : this(Create(model, maxBatch)) { }

        static ZooSafeHandle Create(Model model, int maxBatch)
        {
            var batch = Size.Count(maxBatch, "maxBatch", "zoo_keyframes_runner_new");
            bool e = false;
            try
            {
                IntPtr p = IntPtr.Zero;
                Errors.Check(ZooNative.zoo_keyframes_runner_new((Native.ZooModel*)Enter(model, ref e), batch, (Native.ZooKeyframesRunner**)&p), model);
                return Wrap(HandleKind.KeyframesRunner, p);
            }
            finally { Exit(model, e); }
        }

        /// <summary>The values as size_t (a negative key frame becomes a huge one, which the runtime refuses by its index); with <paramref name="counts"/> a negative value is refused here as a negative count.</summary>
        static Span<UIntPtr> Sizes(ref UIntPtr[] scratch, ReadOnlySpan<int> values, string counts = null)
        {
            if (counts != null)
                for (int i = 0; i < values.Length; i++)
                    if (values[i] < 0) Size.Count(values[i], counts + "[" + i + "]", "zoo_keyframes_complete_batch");
            var s = new Span<UIntPtr>(Size.Fit(ref scratch, values.Length), 0, values.Length);
            for (int i = 0; i < values.Length; i++) s[i] = Size.Of(values[i]);
            return s;
        }

        /// <summary>
        /// Completes one character's keys (<c>zoo_keyframes_complete</c>): <paramref name="keyFrames"/>
        /// strictly increasing from 0, <paramref name="poses"/> D per key, <paramref name="fixedGroups"/>
        /// empty for whole keys or G flags per key (1: the key fixes the group, 0: leaves it free; a model with
        /// key groups only), <paramref name="output"/> (last key frame + 1) * D.
        /// </summary>
        public void Complete(ReadOnlySpan<int> keyFrames, ReadOnlySpan<float> poses, ReadOnlySpan<byte> fixedGroups, Span<float> output)
        {
            var f = Sizes(ref frames, keyFrames);
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (UIntPtr* fp = &MemoryMarshal.GetReference(f))
                fixed (float* pp = &MemoryMarshal.GetReference(poses))
                fixed (byte* xp = &MemoryMarshal.GetReference(fixedGroups))
                fixed (float* op = &MemoryMarshal.GetReference(output))
                    s = ZooNative.zoo_keyframes_complete((Native.ZooKeyframesRunner*)Enter(this, ref e), fp, Size.Of(f.Length), pp, Size.Of(poses.Length),
                        xp, Size.Of(fixedGroups.Length), op, Size.Of(output.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }

        /// <summary>
        /// Completes the keys of several characters in one graph call per frame
        /// (<c>zoo_keyframes_complete_batch</c>): character c has <paramref name="keyCounts"/>[c] keys and
        /// the other buffers hold the characters' buffers of <see cref="Complete"/> one after the other.
        /// </summary>
        public void CompleteBatch(ReadOnlySpan<int> keyCounts, ReadOnlySpan<int> keyFrames, ReadOnlySpan<float> poses, ReadOnlySpan<byte> fixedGroups, Span<float> output)
        {
            var k = Sizes(ref counts, keyCounts, "keyCounts");
            var f = Sizes(ref frames, keyFrames);
            bool e = false;
            try
            {
                ZooStatus s;
                fixed (UIntPtr* kp = &MemoryMarshal.GetReference(k))
                fixed (UIntPtr* fp = &MemoryMarshal.GetReference(f))
                fixed (float* pp = &MemoryMarshal.GetReference(poses))
                fixed (byte* xp = &MemoryMarshal.GetReference(fixedGroups))
                fixed (float* op = &MemoryMarshal.GetReference(output))
                    s = ZooNative.zoo_keyframes_complete_batch((Native.ZooKeyframesRunner*)Enter(this, ref e), kp, Size.Of(k.Length), fp, Size.Of(f.Length),
                        pp, Size.Of(poses.Length), xp, Size.Of(fixedGroups.Length), op, Size.Of(output.Length));
                Errors.Check(s, this);
            }
            finally { Exit(this, e); }
        }
    }
}
