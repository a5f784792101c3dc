// Engine-side pose helpers that need no native call: a reusable pose buffer, the root of a pose
// given in world space (the runtime's EnginePose::set_world, for a Y-up engine frame), and the
// mapping of an engine's bones to the model's joints by name.
using System;
using System.Collections.Generic;
using System.Runtime.InteropServices;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// Buffers for <see cref="Count"/> engine poses of <see cref="Joints"/> joints, allocated once:
    /// a root each, 4K rotation values each (<c>x y z w</c>, the layout of Unity's <c>Quaternion</c>:
    /// <c>MemoryMarshal.Cast&lt;float, Quaternion&gt;(buffer.Rotations)</c> reads them without copying)
    /// and <see cref="ContactsPerPose"/> contact bytes each.
    /// </summary>
    public sealed class PoseBuffer
    {
        /// <summary>Poses N.</summary>
        public readonly int Count;
        /// <summary>Joints K per pose.</summary>
        public readonly int Joints;
        /// <summary>Contact bytes per pose (2 for synthesis and control, 4 for stitching, 0 for transitions).</summary>
        public readonly int ContactsPerPose;
        /// <summary>One root per pose.</summary>
        public readonly ZooRootMotion[] Roots;
        /// <summary>4K rotation values per pose, pose-major.</summary>
        public readonly float[] Rotations;
        /// <summary>Contact bytes (1: foot on the ground), pose-major.</summary>
        public readonly byte[] Contacts;

        /// <summary>
        /// Buffers for <paramref name="count"/> poses of <paramref name="joints"/> joints, rotations the identity.
        /// A negative argument, or buffers larger than an array holds (2 GiB), is refused with an
        /// <see cref="ArgumentOutOfRangeException"/> before anything is allocated.
        /// </summary>
        public PoseBuffer(int count, int joints, int contactsPerPose = 0)
        {
            Check(count, joints, contactsPerPose);
            Count = count;
            Joints = joints;
            ContactsPerPose = contactsPerPose;
            Roots = new ZooRootMotion[count];
            Rotations = new float[count * joints * 4];
            Contacts = new byte[count * contactsPerPose];
            for (int i = 0; i < count; i++) Roots[i].RootRotation = ZooFloat4.Identity;
            for (int i = 3; i < Rotations.Length; i += 4) Rotations[i] = 1f;
        }

        /// <summary>The largest array the buffers may use, in bytes (2 GiB less one: what every .NET runtime Unity uses allocates).</summary>
        const long MaxArrayBytes = int.MaxValue;

        static void Check(int count, int joints, int contactsPerPose)
        {
            Size.Count(count, "count", "PoseBuffer");
            Size.Count(joints, "joints", "PoseBuffer");
            Size.Count(contactsPerPose, "contactsPerPose", "PoseBuffer");
            const int RootBytes = 14 * sizeof(float);
            long rotations = (long)count * joints;
            string what = null, name = "count";
            int value = count;
            if ((long)count * RootBytes > MaxArrayBytes) what = count + " roots of " + RootBytes + " bytes";
            else if (rotations > MaxArrayBytes / (4 * sizeof(float)))
            {
                what = count + " * " + joints + " rotations of 16 bytes";
                if (joints > count) { name = "joints"; value = joints; }
            }
            else if ((long)count * contactsPerPose > MaxArrayBytes)
            {
                what = count + " * " + contactsPerPose + " contact bytes";
                if (contactsPerPose > count) { name = "contactsPerPose"; value = contactsPerPose; }
            }
            if (what != null)
                throw new ArgumentOutOfRangeException(name, value, "PoseBuffer: " + what + " are more than one array holds (" + MaxArrayBytes
                    + " bytes); a batch holds at most ZOO_MAX_BATCH (" + ZooNative.ZOO_MAX_BATCH + ") characters: use several buffers");
        }

        /// <summary>The 4K rotation values of pose <paramref name="pose"/>.</summary>
        public Span<float> RotationsOf(int pose)
        {
            return new Span<float>(Rotations, pose * Joints * 4, Joints * 4);
        }

        /// <summary>The rotations of every pose as quaternions (no copy).</summary>
        public Span<ZooFloat4> Quaternions { get { return MemoryMarshal.Cast<float, ZooFloat4>(Rotations.AsSpan()); } }

        /// <summary>Local rotation of joint <paramref name="joint"/> in pose <paramref name="pose"/>.</summary>
        public ZooFloat4 Rotation(int pose, int joint)
        {
            int at = (pose * Joints + joint) * 4;
            return new ZooFloat4(Rotations[at], Rotations[at + 1], Rotations[at + 2], Rotations[at + 3]);
        }

        /// <summary>Sets the local rotation of joint <paramref name="joint"/> in pose <paramref name="pose"/>.</summary>
        public void SetRotation(int pose, int joint, ZooFloat4 q)
        {
            int at = (pose * Joints + joint) * 4;
            Rotations[at] = q.X;
            Rotations[at + 1] = q.Y;
            Rotations[at + 2] = q.Z;
            Rotations[at + 3] = q.W;
        }
    }

    /// <summary>Quaternion and root arithmetic of engine poses in a Y-up frame (Unity's, zoo's), in single precision as the runtime's.</summary>
    public static class PoseMath
    {
        /// <summary>The Hamilton product <c>a * b</c>.</summary>
        public static ZooFloat4 Multiply(ZooFloat4 a, ZooFloat4 b)
        {
            return new ZooFloat4(
                a.W * b.X + a.X * b.W + a.Y * b.Z - a.Z * b.Y,
                a.W * b.Y - a.X * b.Z + a.Y * b.W + a.Z * b.X,
                a.W * b.Z + a.X * b.Y - a.Y * b.X + a.Z * b.W,
                a.W * b.W - a.X * b.X - a.Y * b.Y - a.Z * b.Z);
        }

        /// <summary>The inverse of a unit quaternion (its conjugate).</summary>
        public static ZooFloat4 Inverse(ZooFloat4 q)
        {
            return new ZooFloat4(-q.X, -q.Y, -q.Z, q.W);
        }

        /// <summary><paramref name="q"/> scaled to unit length.</summary>
        public static ZooFloat4 Normalize(ZooFloat4 q)
        {
            var n = (float)Math.Sqrt(q.X * q.X + q.Y * q.Y + q.Z * q.Z + q.W * q.W);
            return new ZooFloat4(q.X / n, q.Y / n, q.Z / n, q.W / n);
        }

        /// <summary><paramref name="v"/> rotated by the unit quaternion <paramref name="q"/>.</summary>
        public static ZooFloat3 Rotate(ZooFloat4 q, ZooFloat3 v)
        {
            // v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
            float tx = 2f * (q.Y * v.Z - q.Z * v.Y), ty = 2f * (q.Z * v.X - q.X * v.Z), tz = 2f * (q.X * v.Y - q.Y * v.X);
            return new ZooFloat3(
                v.X + q.W * tx + (q.Y * tz - q.Z * ty),
                v.Y + q.W * ty + (q.Z * tx - q.X * tz),
                v.Z + q.W * tz + (q.X * ty - q.Y * tx));
        }

        /// <summary>The rotation about +Y of <paramref name="q"/> (swing-twist decomposition; the runtime's <c>yaw_part</c>).</summary>
        public static ZooFloat4 YawPart(ZooFloat4 q)
        {
            double y = q.Y, w = q.W, n = Math.Sqrt(y * y + w * w);
            if (n * n < 1e-24) return ZooFloat4.Identity;
            return new ZooFloat4(0f, (float)(y / n), 0f, (float)(w / n));
        }

        /// <summary>
        /// Sets a pose from the hips' world position and rotation, as the runtime's
        /// <c>EnginePose::set_world</c>: the root is the hips on the ground (y = 0) facing the yaw of
        /// their rotation, <see cref="ZooRootMotion.HipsPosition"/> the hips in root space, and the
        /// first rotation of <paramref name="rotations"/> the hips' rotation relative to the root. The
        /// other joints' local rotations are the caller's. Deltas are left as they are.
        /// </summary>
        public static void SetWorld(ZooFloat3 hips, ZooFloat4 hipsRotation, ref ZooRootMotion root, Span<float> rotations)
        {
            var h = Normalize(hipsRotation);
            var yaw = YawPart(h);
            var inverse = Inverse(yaw);
            root.RootPosition = new ZooFloat3(hips.X, 0f, hips.Z);
            root.RootRotation = yaw;
            root.HipsPosition = Rotate(inverse, new ZooFloat3(0f, hips.Y, 0f));
            var local = Normalize(Multiply(inverse, h));
            rotations[0] = local.X;
            rotations[1] = local.Y;
            rotations[2] = local.Z;
            rotations[3] = local.W;
        }

        /// <summary>The hips' world position of a pose: root position + root rotation * hips position.</summary>
        public static ZooFloat3 HipsWorld(ZooRootMotion root)
        {
            var p = Rotate(root.RootRotation, root.HipsPosition);
            return new ZooFloat3(root.RootPosition.X + p.X, root.RootPosition.Y + p.Y, root.RootPosition.Z + p.Z);
        }

        /// <summary>The hips' world rotation of a pose: root rotation * the hips' local rotation (the first of <paramref name="rotations"/>).</summary>
        public static ZooFloat4 HipsWorldRotation(ZooRootMotion root, ReadOnlySpan<float> rotations)
        {
            return Normalize(Multiply(root.RootRotation, new ZooFloat4(rotations[0], rotations[1], rotations[2], rotations[3])));
        }
    }

    /// <summary>The model joint each engine bone drives, found by name.</summary>
    public static class BoneMapping
    {
        /// <summary>
        /// For each model joint, the index in <paramref name="bones"/> of the bone with its name, or
        /// the name <paramref name="renames"/> maps it to (model joint name to engine bone name; null
        /// for none). Every joint needs a bone: otherwise the mapping is refused with a
        /// <see cref="ZooException"/> listing every missing one.
        /// </summary>
        public static int[] Map(IList<string> joints, IList<string> bones, IDictionary<string, string> renames = null)
        {
            var index = new Dictionary<string, int>();
            for (int i = 0; i < bones.Count; i++)
                if (bones[i] != null && !index.ContainsKey(bones[i])) index.Add(bones[i], i);
            var map = new int[joints.Count];
            var missing = new List<string>();
            for (int j = 0; j < joints.Count; j++)
            {
                string name;
                if (renames == null || !renames.TryGetValue(joints[j], out name)) name = joints[j];
                int at;
                if (index.TryGetValue(name, out at)) map[j] = at;
                else missing.Add(name == joints[j] ? "`" + name + "`" : "`" + name + "` (for the model's `" + joints[j] + "`)");
            }
            if (missing.Count > 0)
                throw new ZooException(ZooStatus.InvalidArgument, "BoneMapping.Map: the character has no bone for " + missing.Count + " of the model's " + joints.Count
                    + " joints: " + string.Join(", ", missing) + "; rename the bones or map the model's joint names to yours in a bone map");
            return map;
        }
    }
}
