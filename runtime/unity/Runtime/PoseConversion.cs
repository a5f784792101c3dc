// Poses and positions between two coordinate frames, converted by the runtime
// (zoo_pose_convert, zoo_positions_convert: zoo_runtime::Conversion), in place, allocation-free.
using System;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// The conversion of engine poses and positions from one <see cref="ZooCoordinateFrame"/> to
    /// another, e.g. from a model's (<see cref="Model.Frame"/>: zoo's centimetres, right-handed,
    /// Y up) to Unity's (<see cref="ZooCoordinateFrame.Unity"/>: metres, left-handed, Y up):
    /// positions scaled and re-axed, rotations conjugated, turns reversed by a change of
    /// handedness. Every call converts in place and allocates nothing. Thread-safe.
    /// </summary>
    public sealed unsafe class PoseConversion
    {
        readonly ZooCoordinateFrame from;
        readonly ZooCoordinateFrame to;

        /// <summary>The conversion from <paramref name="from"/> to <paramref name="to"/> (checked by the runtime at the first call).</summary>
        public PoseConversion(ZooCoordinateFrame from, ZooCoordinateFrame to)
        {
            this.from = from;
            this.to = to;
        }

        /// <summary>The source frame.</summary>
        public ZooCoordinateFrame From { get { return from; } }

        /// <summary>The target frame.</summary>
        public ZooCoordinateFrame To { get { return to; } }

        /// <summary>The conversion back.</summary>
        public PoseConversion Inverse { get { return new PoseConversion(to, from); } }

        /// <summary>Converts <paramref name="roots"/> and their <c>4K</c> rotations each in place (<c>zoo_pose_convert</c>); either may be empty.</summary>
        public void Poses(Span<ZooRootMotion> roots, Span<float> rotations)
        {
            var f = from;
            var t = to;
            ZooStatus s;
            fixed (ZooRootMotion* r = &MemoryMarshal.GetReference(roots))
            fixed (float* q = &MemoryMarshal.GetReference(rotations))
                s = ZooNative.zoo_pose_convert(&f, &t, r, Size.Of(roots.Length), q, Size.Of(rotations.Length));
            Errors.Check(s);
        }

        /// <summary>Converts one root in place.</summary>
        public void Root(ref ZooRootMotion root)
        {
            var f = from;
            var t = to;
            ZooStatus s;
            fixed (ZooRootMotion* r = &root) s = ZooNative.zoo_pose_convert(&f, &t, r, (UIntPtr)1, null, UIntPtr.Zero);
            Errors.Check(s);
        }

        /// <summary>Converts <c>x y z</c> positions in place (<c>zoo_positions_convert</c>): global joint positions, skeleton offsets.</summary>
        public void Positions(Span<float> positions)
        {
            var f = from;
            var t = to;
            ZooStatus s;
            fixed (float* p = &MemoryMarshal.GetReference(positions))
                s = ZooNative.zoo_positions_convert(&f, &t, p, Size.Of(positions.Length));
            Errors.Check(s);
        }

        /// <summary>A position, converted.</summary>
        public ZooFloat3 Position(ZooFloat3 position)
        {
            Positions(new Span<float>(&position, 3));
            return position;
        }

        /// <summary>A rotation (<c>x y z w</c>), converted.</summary>
        public ZooFloat4 Rotation(ZooFloat4 rotation)
        {
            Poses(Span<ZooRootMotion>.Empty, new Span<float>(&rotation, 4));
            return rotation;
        }

        /// <summary>An angle about the up axis (a yaw, a heading), converted: reversed by a change of handedness.</summary>
        public float Yaw(float yaw)
        {
            var root = new ZooRootMotion { DeltaYaw = yaw, RootRotation = ZooFloat4.Identity, HipsPosition = default(ZooFloat3) };
            Root(ref root);
            return root.DeltaYaw;
        }

        /// <summary>Converts the whole rotations of <paramref name="rotations"/> (a trailing part of fewer than 4 values is left for the call that refuses its length).</summary>
        internal void RotationsLenient(Span<float> rotations)
        {
            Poses(Span<ZooRootMotion>.Empty, rotations.Slice(0, rotations.Length - rotations.Length % 4));
        }

        /// <summary>Converts the whole positions of <paramref name="positions"/> (a trailing part of fewer than 3 values is left for the call that refuses its length).</summary>
        internal void PositionsLenient(Span<float> positions)
        {
            Positions(positions.Slice(0, positions.Length - positions.Length % 3));
        }
    }
}
