// A character that plays a learned transition (RTN) from its current pose to a frame of a target
// clip. Wrapper calls: Model.Load, Model.TransitionInfo, Model.JointNames; new TransitionRunner,
// new TransitionCharacters(model, 1, ZooCoordinateFrame.Unity); TransitionCharacters.StartPosed,
// StepPosed, FramesLeft; PoseBuffer; ZooRig (Read, Apply); Dispose. Everything else is Unity.
using System.IO;
using UnityEngine;
using Zoo.Native;
using Zoo.Unity;

namespace Zoo.Samples
{
    /// <summary>
    /// Put it on a character whose bones are named as the model's joints (or map them with a
    /// <see cref="ZooBoneMap"/>), set the model file (under StreamingAssets) and call
    /// <see cref="PlayTransition"/>: the character moves from its current pose to the clip's frame
    /// over the model's trained transition length, at the model's frame rate. While no transition
    /// plays, it records its own pose as the transition's context.
    /// </summary>
    [DisallowMultipleComponent]
    public sealed class ZooCharacter : MonoBehaviour
    {
        [Tooltip("The exported transition model (zoo export --onnx), relative to StreamingAssets.")]
        [SerializeField] string modelFile = "rtn.onnx";
        [Tooltip("The character's hips: the root bone of the mapped hierarchy.")]
        [SerializeField] Transform hips;
        [Tooltip("Bone names for model joints named otherwise (optional).")]
        [SerializeField] ZooBoneMap boneMap;

        Model model;
        TransitionRunner runner;
        TransitionCharacters character;
        ZooRig rig;
        PoseBuffer history, context, target, next, frame;
        int recorded, length;
        float clock, dt;
        bool playing;

        /// <summary>Whether a transition is playing.</summary>
        public bool Playing { get { return playing; } }

        void Awake()
        {
            // On Android StreamingAssets is inside the APK: read the bytes with UnityWebRequest and
            // use Model.FromBytes instead (Documentation~/zoo.md, Loading a model).
            model = Model.Load(Path.Combine(Application.streamingAssetsPath, modelFile));
            var info = model.TransitionInfo;
            length = info.TransitionFrameCount;
            dt = 1f / model.Fps;
            // Refuses a character that lacks any of the model's bones, with their list.
            rig = new ZooRig(hips, model.JointNames(), boneMap != null ? boneMap.ToDictionary() : null);
            runner = new TransitionRunner(model, 1);
            character = new TransitionCharacters(model, 1, ZooCoordinateFrame.Unity);
            int k = model.Joints;
            history = new PoseBuffer(info.PastFrameCount, k);
            context = new PoseBuffer(info.PastFrameCount, k);
            target = new PoseBuffer(1, k);
            next = new PoseBuffer(1, k);
            frame = new PoseBuffer(1, k);
        }

        /// <summary>Starts a transition from the recorded context to frame <paramref name="targetFrame"/> of <paramref name="clip"/> (a generic clip of this character).</summary>
        public void PlayTransition(AnimationClip clip, int targetFrame)
        {
            if (recorded == 0) Record();
            // Sample the clip's target frame and the one after it on the hierarchy, then put the
            // current pose back.
            rig.Read(ref frame.Roots[0], frame.RotationsOf(0));
            clip.SampleAnimation(gameObject, targetFrame / clip.frameRate);
            rig.Read(ref target.Roots[0], target.RotationsOf(0));
            clip.SampleAnimation(gameObject, (targetFrame + 1) / clip.frameRate);
            rig.Read(ref next.Roots[0], next.RotationsOf(0));
            rig.Apply(frame.Roots[0], frame.RotationsOf(0));
            // The context oldest first (the first frames repeat until enough are recorded).
            int p = context.Count, have = Mathf.Min(recorded, p);
            for (int i = 0; i < p; i++)
            {
                int from = (recorded - have + Mathf.Max(0, i - (p - have))) % p;
                context.Roots[i] = history.Roots[from];
                history.RotationsOf(from).CopyTo(context.RotationsOf(i));
            }
            character.StartPosed(runner, context.Roots, context.Rotations, target.Roots, target.Rotations, next.Roots, next.Rotations, length);
            playing = true;
            clock = 0f;
        }

        void Update()
        {
            clock += Time.deltaTime;
            while (clock >= dt)
            {
                clock -= dt;
                if (playing)
                {
                    character.StepPosed(runner, frame.Roots, frame.Rotations);
                    rig.Apply(frame.Roots[0], frame.Rotations);
                    playing = character.FramesLeft(0) > 0;
                }
                else
                {
                    Record();
                }
            }
        }

        /// <summary>Records the current pose into the context ring.</summary>
        void Record()
        {
            int at = recorded % history.Count;
            rig.Read(ref history.Roots[at], history.RotationsOf(at));
            recorded++;
        }

        void OnDestroy()
        {
            if (character != null) character.Dispose();
            if (runner != null) runner.Dispose();
            if (model != null) model.Dispose();
        }
    }
}
