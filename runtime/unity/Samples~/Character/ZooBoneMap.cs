// A bone map asset: the character's bone name for each model joint whose name differs
// (Assets > Create > zoo > Bone Map). No wrapper calls; ZooRig reads it through ToDictionary.
using System;
using System.Collections.Generic;
using UnityEngine;

namespace Zoo.Samples
{
    /// <summary>Renames model joints to a character's bone names (joints not listed keep their name).</summary>
    [CreateAssetMenu(fileName = "ZooBoneMap", menuName = "zoo/Bone Map")]
    public sealed class ZooBoneMap : ScriptableObject
    {
        /// <summary>One model joint and the bone that plays it.</summary>
        [Serializable]
        public struct Entry
        {
            /// <summary>The model's joint name (Model.JointNames()).</summary>
            public string modelJoint;
            /// <summary>The character's bone (Transform) name.</summary>
            public string bone;
        }

        /// <summary>The renamed joints.</summary>
        public Entry[] entries = new Entry[0];

        /// <summary>The map as model joint to bone name.</summary>
        public Dictionary<string, string> ToDictionary()
        {
            var map = new Dictionary<string, string>();
            foreach (var e in entries)
                if (!string.IsNullOrEmpty(e.modelJoint)) map[e.modelJoint] = e.bone;
            return map;
        }
    }
}
