// The Unity glue of the package (assembly Zoo.Unity, the only one that references UnityEngine):
// a character's Transform hierarchy mapped to a model's joints by bone name, read into engine
// poses and posed from them. Wrapper calls: BoneMapping.Map (the mapping, refusing missing bones
// with their list), PoseMath.SetWorld (reading the hips), PoseMath.HipsWorld and
// PoseMath.HipsWorldRotation (posing them). Poses are in Unity's frame: make the characters with
// ZooCoordinateFrame.Unity.
using System;
using System.Collections.Generic;
using UnityEngine;
using Zoo.Native;

namespace Zoo.Unity
{
    /// <summary>
    /// A character's bones in the model's joint order, found by name under a root Transform
    /// (<see cref="BoneMapping.Map"/>). The model's local rotations are relative to a rest pose
    /// whose bones have no rotation of their own (BVH, zoo's glTF): import the character from the
    /// model's training skeleton, or retarget first.
    /// </summary>
    public sealed class ZooRig
    {
        readonly Transform[] bones;

        /// <summary>Maps the bones under <paramref name="root"/> (itself included) to <paramref name="joints"/> (<c>Model.JointNames()</c>), renamed by <paramref name="renames"/> (model joint to bone name; null for none).</summary>
        public ZooRig(Transform root, IList<string> joints, IDictionary<string, string> renames)
        {
            var transforms = root.GetComponentsInChildren<Transform>(true);
            var names = new string[transforms.Length];
            for (int i = 0; i < transforms.Length; i++) names[i] = transforms[i].name;
            var map = BoneMapping.Map(joints, names, renames);
            bones = new Transform[map.Length];
            for (int j = 0; j < map.Length; j++) bones[j] = transforms[map[j]];
        }

        /// <summary>The bone of each model joint (the hips first).</summary>
        public Transform[] Bones { get { return bones; } }

        /// <summary>Reads the character's current pose (Unity's frame): the root from the hips' world transform, the other joints' local rotations.</summary>
        public void Read(ref ZooRootMotion root, Span<float> rotations)
        {
            var hips = bones[0];
            var p = hips.position;
            var q = hips.rotation;
            PoseMath.SetWorld(new ZooFloat3(p.x, p.y, p.z), new ZooFloat4(q.x, q.y, q.z, q.w), ref root, rotations);
            for (int j = 1; j < bones.Length; j++)
            {
                var r = bones[j].localRotation;
                rotations[4 * j] = r.x;
                rotations[4 * j + 1] = r.y;
                rotations[4 * j + 2] = r.z;
                rotations[4 * j + 3] = r.w;
            }
        }

        /// <summary>Poses the character (Unity's frame): the hips in world space from the root, the other joints' local rotations.</summary>
        public void Apply(ZooRootMotion root, ReadOnlySpan<float> rotations)
        {
            var p = PoseMath.HipsWorld(root);
            var q = PoseMath.HipsWorldRotation(root, rotations);
            bones[0].SetPositionAndRotation(new Vector3(p.X, p.Y, p.Z), new Quaternion(q.X, q.Y, q.Z, q.W));
            for (int j = 1; j < bones.Length; j++)
                bones[j].localRotation = new Quaternion(rotations[4 * j], rotations[4 * j + 1], rotations[4 * j + 2], rotations[4 * j + 3]);
        }
    }
}
