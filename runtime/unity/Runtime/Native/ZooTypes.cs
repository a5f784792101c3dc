// The types of the C ABI (runtime/capi/include/zoo.h, C ABI version 3), one C# type per C type with
// the same layout: enums (int-sized), data structs (sequential, C field order; a `float name[N]`
// array is a ZooFloatN), the opaque handle structs (only ever behind a pointer) and the delegate of
// the function-pointer typedef ZooLogCallback. Field names are the C names in PascalCase, enum
// members the C names without the enum's prefix in PascalCase. The binding check
// (Tests~/BindingCheck.cs) compares every one of them with the header; the properties below add
// nothing to the layout.
using System;
using System.Runtime.InteropServices;

namespace Zoo.Native
{
    /// <summary>Result of a call (<c>ZooStatus</c>).</summary>
    public enum ZooStatus
    {
        /// <summary>Success.</summary>
        Ok = 0,
        /// <summary>A required pointer (handle, buffer or output) was NULL.</summary>
        NullPointer = 1,
        /// <summary>An argument is wrong: a buffer of the wrong length, a non-finite value, a count of zero or above <c>ZOO_MAX_BATCH</c>, a value outside its enum.</summary>
        InvalidArgument = 2,
        /// <summary>The model file cannot be read or is not an exported zoo model of a task this library runs.</summary>
        LoadFailed = 3,
        /// <summary>The model is of another task than the function's.</summary>
        WrongModel = 4,
        /// <summary>The call does not fit where the handle stands.</summary>
        InvalidState = 5,
        /// <summary>The graph failed to run.</summary>
        RunFailed = 6,
        /// <summary>The requested value is not known yet, or the model has no such thing.</summary>
        NotAvailable = 7,
        /// <summary>An internal error (a caught panic): please report it with the message.</summary>
        Panic = 8,
    }

    /// <summary>What a model does (<c>ZooTask</c>).</summary>
    public enum ZooTask
    {
        /// <summary>No model.</summary>
        None = 0,
        /// <summary>Transitions between poses (RTN).</summary>
        Transition = 1,
        /// <summary>Keyframe completion (ARNN).</summary>
        Keyframes = 2,
        /// <summary>Refining stitched locomotion (RMR).</summary>
        Stitch = 3,
        /// <summary>Random motion synthesis (RNN-GMM) and its speed / facing control.</summary>
        Synthesis = 4,
    }

    /// <summary>The up axis of positions and rotations (<c>ZooUpAxis</c>).</summary>
    public enum ZooUpAxis
    {
        /// <summary>+Y up (zoo, BVH, Unity, Maya).</summary>
        Y = 0,
        /// <summary>+Z up (Blender, Unreal).</summary>
        Z = 1,
    }

    /// <summary>The handedness of the axes (<c>ZooHandedness</c>).</summary>
    public enum ZooHandedness
    {
        /// <summary>Right-handed (zoo, BVH, Blender, Maya, Godot).</summary>
        Right = 0,
        /// <summary>Left-handed (Unity, Unreal).</summary>
        Left = 1,
    }

    /// <summary>The severity of a log message (<c>ZooLogLevel</c>: the <c>level</c> of <see cref="ZooLogCallback"/>, the <c>max_level</c> of <c>zoo_set_log_callback</c>).</summary>
    public enum ZooLogLevel
    {
        /// <summary>Something failed and was worked around or reported as a status.</summary>
        Error = 1,
        /// <summary>Something the engine programmer should know (the library degraded or ignored something).</summary>
        Warning = 2,
        /// <summary>What the library does, once per model or handle (loading, graph optimisation).</summary>
        Info = 3,
        /// <summary>Details for diagnosing a problem; frequent.</summary>
        Debug = 4,
    }

    /// <summary>
    /// The logging callback of <c>zoo_set_log_callback</c> (<c>ZooLogCallback</c>): <paramref name="level"/> a
    /// <see cref="ZooLogLevel"/> value, <paramref name="message"/> a NUL-terminated UTF-8 string valid only during
    /// the call, <paramref name="user_data"/> the pointer given with the callback. Called from any thread that calls
    /// the library; it must not call back into it. <c>Zoo.Library.SetLogCallback</c> wires one for you.
    /// </summary>
    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    public unsafe delegate void ZooLogCallback(int level, byte* message, void* user_data);

    /// <summary>Three floats: a C <c>float[3]</c> (a position); the layout of Unity's <c>Vector3</c>.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooFloat3
    {
        /// <summary>x.</summary>
        public float X;
        /// <summary>y.</summary>
        public float Y;
        /// <summary>z.</summary>
        public float Z;

        /// <summary>The three values.</summary>
        public ZooFloat3(float x, float y, float z)
        {
            X = x;
            Y = y;
            Z = z;
        }
    }

    /// <summary>Four floats: a C <c>float[4]</c> (a quaternion <c>x y z w</c>); the layout of Unity's <c>Quaternion</c>.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooFloat4
    {
        /// <summary>x.</summary>
        public float X;
        /// <summary>y.</summary>
        public float Y;
        /// <summary>z.</summary>
        public float Z;
        /// <summary>w.</summary>
        public float W;

        /// <summary>The four values.</summary>
        public ZooFloat4(float x, float y, float z, float w)
        {
            X = x;
            Y = y;
            Z = z;
            W = w;
        }

        /// <summary>The identity rotation.</summary>
        public static ZooFloat4 Identity { get { return new ZooFloat4(0f, 0f, 0f, 1f); } }
    }

    /// <summary>
    /// The root of an engine pose (<c>ZooRootMotion</c>): the hips projected on the ground and their
    /// facing, the root motion since the previous frame, and the hips in root space. The joints'
    /// local rotations travel in a separate <c>4K</c> float buffer per pose. On input only
    /// <see cref="RootPosition"/>, <see cref="RootRotation"/> and <see cref="HipsPosition"/> are read.
    /// </summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooRootMotion
    {
        /// <summary>Hips on the ground, model (or engine) units.</summary>
        public ZooFloat3 RootPosition;
        /// <summary>Facing: a rotation about the up axis, quaternion <c>x y z w</c>.</summary>
        public ZooFloat4 RootRotation;
        /// <summary>Root displacement since the previous frame, in the previous frame's root space.</summary>
        public ZooFloat3 DeltaPosition;
        /// <summary>Turn since the previous frame about the up axis, radians.</summary>
        public float DeltaYaw;
        /// <summary>The hips' position in root space.</summary>
        public ZooFloat3 HipsPosition;
    }

    /// <summary>
    /// A coordinate frame: length unit, up axis and handedness (<c>ZooCoordinateFrame</c>). The axis and the
    /// handedness are stored as integers (C's <c>uint32_t</c>) holding a <see cref="ZooUpAxis"/> and a
    /// <see cref="ZooHandedness"/> value, so that a value from outside the enum reaches the runtime, which refuses
    /// it by name, rather than being misread: make frames with the constructor
    /// (<c>new ZooCoordinateFrame(1f, ZooUpAxis.Y, ZooHandedness.Left)</c>) and read them with
    /// <see cref="Up"/> and <see cref="Hand"/>.
    /// </summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooCoordinateFrame
    {
        /// <summary>Metres per length unit (0.01: centimetres, 1: metres); finite and positive.</summary>
        public float MetresPerUnit;
        /// <summary>The up axis: a <see cref="ZooUpAxis"/> value (<see cref="Up"/> reads and writes it as one); any other value is refused by the runtime.</summary>
        public uint UpAxis;
        /// <summary>The handedness: a <see cref="ZooHandedness"/> value (<see cref="Hand"/> reads and writes it as one); any other value is refused by the runtime.</summary>
        public uint Handedness;

        /// <summary>A frame.</summary>
        public ZooCoordinateFrame(float metresPerUnit, ZooUpAxis upAxis, ZooHandedness handedness)
        {
            MetresPerUnit = metresPerUnit;
            UpAxis = (uint)upAxis;
            Handedness = (uint)handedness;
        }

        /// <summary><see cref="UpAxis"/> as a <see cref="ZooUpAxis"/>.</summary>
        public ZooUpAxis Up
        {
            get { return (ZooUpAxis)UpAxis; }
            set { UpAxis = (uint)value; }
        }

        /// <summary><see cref="Handedness"/> as a <see cref="ZooHandedness"/>.</summary>
        public ZooHandedness Hand
        {
            get { return (ZooHandedness)Handedness; }
            set { Handedness = (uint)value; }
        }

        /// <summary>Unity's frame: metres, Y up, left-handed.</summary>
        public static ZooCoordinateFrame Unity { get { return new ZooCoordinateFrame(1f, ZooUpAxis.Y, ZooHandedness.Left); } }

        /// <summary>zoo's data frame: centimetres, Y up, right-handed (bandai2, the synthetic data).</summary>
        public static ZooCoordinateFrame ZooCentimetres { get { return new ZooCoordinateFrame(0.01f, ZooUpAxis.Y, ZooHandedness.Right); } }

        /// <summary>A readable form, e.g. <c>0.01 m/unit, Y up, Right-handed</c> (a value outside the enums as its number).</summary>
        public override string ToString()
        {
            return MetresPerUnit.ToString(System.Globalization.CultureInfo.InvariantCulture) + " m/unit, " + Up + " up, " + Hand + "-handed";
        }
    }

    /// <summary>What every model is, whatever its task (<c>ZooModelInfo</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooModelInfo
    {
        /// <summary>The model's task.</summary>
        public ZooTask Task;
        /// <summary>Number of joints K of the model's skeleton.</summary>
        public UIntPtr Joints;
        /// <summary>Frames per second of the model's motion.</summary>
        public float Fps;
        /// <summary>Metres per model unit of every position (0.01: centimetres).</summary>
        public float MetresPerUnit;
        /// <summary>The up axis of positions and rotations.</summary>
        public ZooUpAxis UpAxis;
        /// <summary>The handedness of the axes.</summary>
        public ZooHandedness Handedness;
        /// <summary>The format version of the file.</summary>
        public uint FormatVersion;

        /// <summary><see cref="Joints"/> as an int.</summary>
        public int JointCount { get { return (int)Joints.ToUInt64(); } }

        /// <summary>The model's coordinate frame.</summary>
        public ZooCoordinateFrame Frame { get { return new ZooCoordinateFrame(MetresPerUnit, UpAxis, Handedness); } }
    }

    /// <summary>What a transition model expects (<c>ZooTransitionInfo</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooTransitionInfo
    {
        /// <summary>Context frames the model was trained with.</summary>
        public UIntPtr PastFrames;
        /// <summary>Transition length the model was trained on.</summary>
        public UIntPtr TransitionFrames;
        /// <summary>Frames of the target blend at the end of a transition.</summary>
        public UIntPtr TargetBlend;

        /// <summary><see cref="PastFrames"/> as an int.</summary>
        public int PastFrameCount { get { return (int)PastFrames.ToUInt64(); } }
        /// <summary><see cref="TransitionFrames"/> as an int.</summary>
        public int TransitionFrameCount { get { return (int)TransitionFrames.ToUInt64(); } }
    }

    /// <summary>What a keyframes model expects (<c>ZooKeyframesInfo</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooKeyframesInfo
    {
        /// <summary>Values per pose D: a key and a completed frame are D floats (6 for the lamp).</summary>
        public UIntPtr FrameValues;
        /// <summary>Key groups G a partial key fixes or leaves free; 0: keys are whole poses.</summary>
        public UIntPtr Groups;

        /// <summary><see cref="FrameValues"/> as an int.</summary>
        public int FrameValueCount { get { return (int)FrameValues.ToUInt64(); } }
        /// <summary><see cref="Groups"/> as an int.</summary>
        public int GroupCount { get { return (int)Groups.ToUInt64(); } }
    }

    /// <summary>What a stitching model expects (<c>ZooStitchInfo</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooStitchInfo
    {
        /// <summary>Frames per refined window w.</summary>
        public UIntPtr Window;
        /// <summary>Frames between windows s.</summary>
        public UIntPtr Stride;
        /// <summary>Frames over which each window's first-frame difference is blended away.</summary>
        public UIntPtr BlendFrames;
        /// <summary>Latency of a new stream in frames: the window, the lookahead of its seam guard and foot lock, and the frames they release at once, less one.</summary>
        public UIntPtr Latency;

        /// <summary><see cref="Window"/> as an int.</summary>
        public int WindowFrames { get { return (int)Window.ToUInt64(); } }
        /// <summary><see cref="Latency"/> as an int.</summary>
        public int LatencyFrames { get { return (int)Latency.ToUInt64(); } }
    }

    /// <summary>What a synthesis model expects (<c>ZooSynthesisInfo</c>).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooSynthesisInfo
    {
        /// <summary>Values D of a feature frame (a start frame).</summary>
        public UIntPtr FrameValues;
        /// <summary>Whether runners and characters made now refine each generated frame.</summary>
        [MarshalAs(UnmanagedType.U1)]
        public bool HasRefiner;

        /// <summary><see cref="FrameValues"/> as an int.</summary>
        public int FrameValueCount { get { return (int)FrameValues.ToUInt64(); } }
    }

    /// <summary>How controlled characters plan (<c>ZooControlSettings</c>); the wrapper's <c>Zoo.ControlSettings</c> fills it.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct ZooControlSettings
    {
        /// <summary>Frames per planned batch; at least 1.</summary>
        public UIntPtr Batch;
        /// <summary>Standard deviation of the speed term, clip units per second.</summary>
        public float SigmaSpeed;
        /// <summary>Standard deviation of the facing term, radians.</summary>
        public float SigmaHeading;
        /// <summary>Scale of the mixture's standard deviations when drawing.</summary>
        public float Temperature;
        /// <summary>Offsets of a candidate's forward step; NULL and 0: the defaults.</summary>
        public float* SpeedOffsets;
        /// <summary>Number of speed offsets.</summary>
        public UIntPtr SpeedOffsetsLen;
        /// <summary>Offsets of a candidate's turn; NULL and 0: the defaults.</summary>
        public float* TurnOffsets;
        /// <summary>Number of turn offsets.</summary>
        public UIntPtr TurnOffsetsLen;
    }

    /// <summary>A control target of one character (<c>ZooControl</c>), in the model's units and axes.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ZooControl
    {
        /// <summary>Target root speed over the ground, model units per second; finite, >= 0.</summary>
        public float Speed;
        /// <summary>Target facing yaw, radians about +Y (0 faces +Z); finite.</summary>
        public float Heading;

        /// <summary>A control.</summary>
        public ZooControl(float speed, float heading)
        {
            Speed = speed;
            Heading = heading;
        }
    }

    /// <summary>A loaded model of any task (opaque, behind a pointer).</summary>
    public struct ZooModel { }

    /// <summary>Scratch space for running a transition model (opaque).</summary>
    public struct ZooTransitionRunner { }

    /// <summary>The transitions of a batch of characters (opaque).</summary>
    public struct ZooTransitionCharacters { }

    /// <summary>Scratch space for completing keys (opaque).</summary>
    public struct ZooKeyframesRunner { }

    /// <summary>A stitching stream (opaque).</summary>
    public struct ZooStitchStream { }

    /// <summary>Scratch space for stepping synthesis characters (opaque).</summary>
    public struct ZooSynthesisRunner { }

    /// <summary>The generators of a batch of characters (opaque).</summary>
    public struct ZooSynthesisCharacters { }

    /// <summary>Scratch space for stepping controlled characters (opaque).</summary>
    public struct ZooControlRunner { }

    /// <summary>A batch of controlled characters (opaque).</summary>
    public struct ZooControlCharacters { }
}
