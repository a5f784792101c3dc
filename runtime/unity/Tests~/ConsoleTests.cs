// The console test: every task through the safe wrappers on the tiny models tests/unity.rs
// exported, against the outputs the Rust runtime wrote for the same inputs; the bad calls; the
// named cases of C ABI 3 (limits, enum values, loading from memory, the library's version and
// log); the managed allocation of every per-frame call; the per-frame cost against C. Prints one
// summary line per figure and one `case NAME: passed` line per case (tests/unity.rs reads them)
// and returns 1 when anything failed.
using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.IO;
using System.Linq;
using System.Runtime.InteropServices;
using System.Text;
using Zoo.Native;

namespace Zoo.Tests
{
    static unsafe class ConsoleTests
    {
        const float Tolerance = 1e-5f;
        static int failures;

        static void Fail(string message)
        {
            failures++;
            Console.WriteLine("FAIL: " + message);
        }

        static void Expect(bool ok, string message)
        {
            if (!ok) Fail(message);
        }

        /// <summary>The largest |got - want|; a length mismatch fails.</summary>
        static float Worst(ReadOnlySpan<float> got, ReadOnlySpan<float> want, string what)
        {
            if (got.Length != want.Length)
            {
                Fail(what + ": " + got.Length + " values, the Rust runtime's " + want.Length);
                return float.PositiveInfinity;
            }
            float worst = 0f;
            for (int i = 0; i < got.Length; i++)
            {
                var d = Math.Abs(got[i] - want[i]);
                if (!(d <= worst)) worst = float.IsNaN(d) ? float.PositiveInfinity : d;
            }
            if (worst > Tolerance) Fail(what + ": differs from the Rust runtime by " + worst);
            return worst;
        }

        static ReadOnlySpan<float> Floats(ZooRootMotion[] roots)
        {
            return MemoryMarshal.Cast<ZooRootMotion, float>(new ReadOnlySpan<ZooRootMotion>(roots));
        }

        static float WorstBytes(byte[] got, long[] want, string what)
        {
            if (got.Length != want.Length) { Fail(what + ": " + got.Length + " contacts, the Rust runtime's " + want.Length); return float.PositiveInfinity; }
            for (int i = 0; i < got.Length; i++)
                if (got[i] != want[i]) { Fail(what + ": contact " + i + " is " + got[i] + ", the Rust runtime's " + want[i]); return 1f; }
            return 0f;
        }

        /// <summary>Appends the poses of a step to the recording.</summary>
        static void Record(PoseBuffer b, List<ZooRootMotion> roots, List<float> rotations, List<byte> contacts)
        {
            roots.AddRange(b.Roots);
            rotations.AddRange(b.Rotations);
            if (contacts != null) contacts.AddRange(b.Contacts);
        }

        public static int Run(Vectors v, string dir)
        {
            Model.CheckLibrary();
            Console.WriteLine("native library: " + Library.Version + ", C ABI version " + ZooNative.zoo_abi_version());
            using (var rtn = Model.Load(Path.Combine(dir, "rtn.onnx")))
            using (var arnn = Model.Load(Path.Combine(dir, "arnn.onnx")))
            using (var rmr = Model.Load(Path.Combine(dir, "rmr.onnx")))
            using (var syn = Model.Load(Path.Combine(dir, "rnngmm.onnx")))
            {
                Expect(rtn.Task == ZooTask.Transition && arnn.Task == ZooTask.Keyframes && rmr.Task == ZooTask.Stitch && syn.Task == ZooTask.Synthesis,
                    "tasks: " + rtn.Task + " " + arnn.Task + " " + rmr.Task + " " + syn.Task);
                Expect(rtn.QueryTask() == ZooTask.Transition, "zoo_model_task");
                Transition(v, rtn);
                Keyframes(v, arnn);
                Stitch(v, rmr);
                Synthesis(v, syn);
                BadCalls(v, dir, rtn, arnn, rmr, syn);
                Cases(v, dir, rtn, arnn, rmr, syn);
                Allocation(v, rtn, arnn, rmr, syn);
                Timing(v, Path.Combine(dir, "rtn.onnx"), rtn);
            }
            Console.WriteLine(failures == 0 ? "console test: passed" : "console test: " + failures + " failure(s)");
            return failures == 0 ? 0 : 1;
        }

        // Parity with the Rust runtime.

        static void Transition(Vectors v, Model rtn)
        {
            int n = v.Int("tr.n"), length = v.Int("tr.length"), k = rtn.Joints;
            var info = rtn.TransitionInfo;
            Expect(info.PastFrameCount == 10 && info.TransitionFrameCount == length, "zoo_transition_info: " + info.PastFrameCount + ", " + info.TransitionFrameCount);
            Expect(rtn.JointNames().SequenceEqual(v.S("tr.names")), "joint names: " + string.Join(",", rtn.JointNames()));
            var parents = new int[k];
            var offsets = new float[3 * k];
            rtn.GetSkeleton(parents, offsets);
            Expect(parents.SequenceEqual(v.I("tr.parents")), "parents");
            float worst = Worst(offsets, v.F("tr.offsets"), "skeleton offsets");
            rtn.GetSkeleton(parents, offsets, rtn.ToEngine(ZooCoordinateFrame.Unity));
            worst = Math.Max(worst, Worst(offsets, v.F("tr.offsets.unity"), "skeleton offsets in Unity's frame"));
            int values = 0;
            float lastFrame = 0f, lastRelative = 0f;
            var lastPosed = new float[4];
            foreach (var frame in new[] { "posed", "unity" })
            {
                ZooCoordinateFrame? engine = null;
                if (frame == "unity") engine = ZooCoordinateFrame.Unity;
                using (var runner = new TransitionRunner(rtn, n))
                using (var chars = new TransitionCharacters(rtn, n, engine))
                {
                    var p = "tr." + frame;
                    chars.StartPosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length);
                    var b = new PoseBuffer(n, k);
                    var roots = new List<ZooRootMotion>();
                    var rotations = new List<float>();
                    for (int s = 0; s <= length; s++)
                    {
                        Expect(chars.FramesLeft(0) == length + 1 - s, "frames left before step " + s + ": " + chars.FramesLeft(0));
                        chars.StepPosed(runner, b.Roots, b.Rotations);
                        Record(b, roots, rotations, null);
                    }
                    Expect(chars.FramesLeft(1) == 0, "frames left at the end: " + chars.FramesLeft(1));
                    worst = Math.Max(worst, Worst(Floats(roots.ToArray()), Floats(v.Roots(p + ".out")), "transition " + frame + " roots"));
                    worst = Math.Max(worst, Worst(rotations.ToArray(), v.Rotations(p + ".out"), "transition " + frame + " rotations"));
                    values += roots.Count * 14 + rotations.Count;
                    if (frame == "posed")
                    {
                        var miss = v.F("tr.miss");
                        for (int c = 0; c < n; c++)
                        {
                            float mean, max;
                            Expect(chars.TryGetTargetMiss(c, out mean, out max), "target miss known at the end");
                            worst = Math.Max(worst, Worst(new[] { mean, max }, new[] { miss[2 * c], miss[2 * c + 1] }, "target miss"));
                        }
                        lastPosed = LastFrameIsTarget(b, v.Roots(p + ".target"), v.Rotations(p + ".target"), k);
                    }
                }
            }
            foreach (var frame in new[] { "pos", "unity.pos" })
            {
                ZooCoordinateFrame? engine = null;
                if (frame == "unity.pos") engine = ZooCoordinateFrame.Unity;
                using (var runner = new TransitionRunner(rtn, n))
                using (var chars = new TransitionCharacters(rtn, n, engine))
                {
                    var p = "tr." + frame;
                    var target = v.F(p + ".target");
                    chars.Start(runner, v.F(p + ".past"), target, v.F(p + ".next"), length);
                    var poses = new float[n * 3 * k];
                    var all = new List<float>();
                    for (int s = 0; s <= length; s++)
                    {
                        chars.Step(runner, poses);
                        all.AddRange(poses);
                    }
                    worst = Math.Max(worst, Worst(all.ToArray(), v.F(p + ".out"), "transition positions (" + frame + ")"));
                    values += all.Count;
                    if (frame == "pos")
                        for (int i = 0; i < poses.Length; i++)
                        {
                            lastFrame = Math.Max(lastFrame, Math.Abs(poses[i] - target[i]));
                            lastRelative = Math.Max(lastRelative, Math.Abs(poses[i] - target[i]) / Math.Max(1f, Math.Abs(target[i])));
                        }
                }
            }
            // The hips' world transform to an engine pose (what the character sample reads from
            // its Transforms), in Unity's frame.
            var hips = MemoryMarshal.Cast<float, ZooFloat3>(v.F("world.hips").AsSpan());
            var hipsRot = MemoryMarshal.Cast<float, ZooFloat4>(v.F("world.hipsrot").AsSpan());
            var want = v.Roots("world.want");
            var wantRot = v.Rotations("world.want");
            for (int i = 0; i < hips.Length; i++)
            {
                var root = new ZooRootMotion();
                var r = new float[4 * k];
                PoseMath.SetWorld(hips[i], hipsRot[i], ref root, r);
                var w = want[i];
                worst = Math.Max(worst, Worst(new[] { root.RootPosition.X, root.RootPosition.Y, root.RootPosition.Z, root.RootRotation.X, root.RootRotation.Y, root.RootRotation.Z, root.RootRotation.W, root.HipsPosition.X, root.HipsPosition.Y, root.HipsPosition.Z, r[0], r[1], r[2], r[3] },
                    new[] { w.RootPosition.X, w.RootPosition.Y, w.RootPosition.Z, w.RootRotation.X, w.RootRotation.Y, w.RootRotation.Z, w.RootRotation.W, w.HipsPosition.X, w.HipsPosition.Y, w.HipsPosition.Z, wantRot[4 * k * i], wantRot[4 * k * i + 1], wantRot[4 * k * i + 2], wantRot[4 * k * i + 3] },
                    "PoseMath.SetWorld vs EnginePose::from_world, case " + i));
                var back = PoseMath.HipsWorld(root);
                worst = Math.Max(worst, Worst(new[] { back.X, back.Y, back.Z }, new[] { hips[i].X, hips[i].Y, hips[i].Z }, "PoseMath.HipsWorld"));
            }
            Console.WriteLine("parity transition: worst=" + worst.ToString("G3") + " values=" + values + " (posed and positions, model frame and Unity's, " + n + " characters x " + (length + 1) + " frames; skeleton, names, target miss, frames left, SetWorld)");
            Console.WriteLine("last frame: target=" + lastFrame.ToString("G3") + " relative=" + lastRelative.ToString("G3") + " (largest |got - target| of the 30-frame transition's last frame, global positions, model units; relative: / max(1, |target|)) posed: root position " + lastPosed[0].ToString("G3")
                + ", root rotation " + lastPosed[1].ToString("G3") + ", hips " + lastPosed[2].ToString("G3") + ", local rotations " + lastPosed[3].ToString("G3") + " (quaternion components, up to sign)");
        }

        static float MaxDiff(ReadOnlySpan<float> a, ReadOnlySpan<float> b)
        {
            float worst = 0f;
            for (int i = 0; i < a.Length; i++) worst = Math.Max(worst, Math.Abs(a[i] - b[i]));
            return worst;
        }

        /// <summary>The largest differences between the last stepped poses and the targets: root position, root rotation (up to sign), hips position, local rotations (up to sign).</summary>
        static float[] LastFrameIsTarget(PoseBuffer b, ZooRootMotion[] target, float[] targetRotations, int k)
        {
            var worst = new float[4];
            for (int c = 0; c < b.Count; c++)
            {
                var got = b.Roots[c];
                var want = target[c];
                worst[0] = Math.Max(worst[0], MaxDiff(new[] { got.RootPosition.X, got.RootPosition.Y, got.RootPosition.Z }, new[] { want.RootPosition.X, want.RootPosition.Y, want.RootPosition.Z }));
                worst[1] = Math.Max(worst[1], QuatDiff(got.RootRotation, want.RootRotation));
                worst[2] = Math.Max(worst[2], MaxDiff(new[] { got.HipsPosition.X, got.HipsPosition.Y, got.HipsPosition.Z }, new[] { want.HipsPosition.X, want.HipsPosition.Y, want.HipsPosition.Z }));
                for (int j = 0; j < k; j++)
                {
                    int at = (c * k + j) * 4;
                    worst[3] = Math.Max(worst[3], QuatDiff(b.Rotation(c, j), new ZooFloat4(targetRotations[at], targetRotations[at + 1], targetRotations[at + 2], targetRotations[at + 3])));
                }
            }
            return worst;
        }

        static float QuatDiff(ZooFloat4 a, ZooFloat4 b)
        {
            float plus = MaxDiff(new[] { a.X, a.Y, a.Z, a.W }, new[] { b.X, b.Y, b.Z, b.W });
            float minus = MaxDiff(new[] { a.X, a.Y, a.Z, a.W }, new[] { -b.X, -b.Y, -b.Z, -b.W });
            return Math.Min(plus, minus);
        }

        static void Keyframes(Vectors v, Model arnn)
        {
            var info = arnn.KeyframesInfo;
            int d = info.FrameValueCount;
            var counts = v.I("kf.counts");
            var frames = v.I("kf.frames");
            var poses = v.F("kf.poses");
            float worst;
            using (var runner = new KeyframesRunner(arnn, 2))
            {
                var batch = new float[(frames[counts[0] - 1] + 1 + frames[frames.Length - 1] + 1) * d];
                runner.CompleteBatch(counts, frames, poses, ReadOnlySpan<byte>.Empty, batch);
                worst = Worst(batch, v.F("kf.batch"), "keyframes batch");
                var single = new float[(frames[counts[0] - 1] + 1) * d];
                runner.Complete(new ReadOnlySpan<int>(frames, 0, counts[0]), new ReadOnlySpan<float>(poses, 0, counts[0] * d), ReadOnlySpan<byte>.Empty, single);
                worst = Math.Max(worst, Worst(single, v.F("kf.single"), "keyframes single"));
                Expect(arnn.JointNames().SequenceEqual(v.S("kf.names")), "keyframes joint names");
                Console.WriteLine("parity keyframes: worst=" + worst.ToString("G3") + " values=" + (batch.Length + single.Length) + " (2 characters in one batch and one alone, D=" + d + ")");
            }
        }

        static void Stitch(Vectors v, Model rmr)
        {
            int k = rmr.Joints;
            var roots = v.Roots("st.in");
            var rotations = v.Rotations("st.in");
            int frames = roots.Length;
            var outRoots = new ZooRootMotion[frames];
            var outRotations = new float[frames * 4 * k];
            var contacts = new byte[frames * 4];
            rmr.StitchRefine(roots, rotations, true, true, outRoots, outRotations, contacts);
            float worst = Worst(Floats(outRoots), Floats(v.Roots("st.refine")), "stitch refine roots");
            worst = Math.Max(worst, Worst(outRotations, v.Rotations("st.refine"), "stitch refine rotations"));
            worst = Math.Max(worst, WorstBytes(contacts, v.L("st.refine.contacts"), "stitch refine contacts"));
            int values = outRoots.Length * 14 + outRotations.Length;
            using (var stream = new StitchStream(rmr))
            {
                var popped = new List<ZooRootMotion>();
                var poppedRotations = new List<float>();
                var poppedContacts = new List<byte>();
                var root = new ZooRootMotion();
                var q = new float[4 * k];
                var c = new byte[4];
                Expect(!stream.TryPop(ref root, q, c), "nothing to pop before the first push");
                for (int f = 0; f <= frames; f++)
                {
                    if (f < frames) stream.Push(roots[f], new ReadOnlySpan<float>(rotations, f * 4 * k, 4 * k));
                    else stream.Finish();
                    while (stream.Ready)
                    {
                        Expect(stream.TryPop(ref root, q, c), "a ready pose pops");
                        popped.Add(root);
                        poppedRotations.AddRange(q);
                        poppedContacts.AddRange(c);
                    }
                }
                worst = Math.Max(worst, Worst(Floats(popped.ToArray()), Floats(v.Roots("st.stream")), "stitch stream roots"));
                worst = Math.Max(worst, Worst(poppedRotations.ToArray(), v.Rotations("st.stream"), "stitch stream rotations"));
                worst = Math.Max(worst, WorstBytes(poppedContacts.ToArray(), v.L("st.stream.contacts"), "stitch stream contacts"));
                values += popped.Count * 14 + poppedRotations.Count;
            }
            // Inertialized at seams first: whole, and streamed with the seams marked.
            var seams = v.I("st.seams");
            rmr.StitchRefineAtSeams(roots, rotations, seams, true, true, outRoots, outRotations, contacts);
            worst = Math.Max(worst, Worst(Floats(outRoots), Floats(v.Roots("st.seams.refine")), "stitch refine at seams roots"));
            worst = Math.Max(worst, Worst(outRotations, v.Rotations("st.seams.refine"), "stitch refine at seams rotations"));
            using (var stream = new StitchStream(rmr))
            {
                var popped = new List<ZooRootMotion>();
                var poppedRotations = new List<float>();
                var root = new ZooRootMotion();
                var q = new float[4 * k];
                var c = new byte[4];
                for (int f = 0; f <= frames; f++)
                {
                    if (Array.IndexOf(seams, f) >= 0) stream.MarkSeam();
                    if (f < frames) stream.Push(roots[f], new ReadOnlySpan<float>(rotations, f * 4 * k, 4 * k));
                    else stream.Finish();
                    while (stream.TryPop(ref root, q, c))
                    {
                        popped.Add(root);
                        poppedRotations.AddRange(q);
                    }
                }
                worst = Math.Max(worst, Worst(Floats(popped.ToArray()), Floats(v.Roots("st.seams.stream")), "stitch stream at seams roots"));
                worst = Math.Max(worst, Worst(poppedRotations.ToArray(), v.Rotations("st.seams.stream"), "stitch stream at seams rotations"));
                values += 2 * (outRoots.Length * 14 + outRotations.Length);
            }
            Expect(rmr.JointNames().SequenceEqual(v.S("st.names")), "stitch joint names");
            Expect(!rmr.StitchPreBlend, "the tiny stitching model refines the raw concatenation (stitch.pre_blend false)");
            Console.WriteLine("parity stitch: worst=" + worst.ToString("G3") + " values=" + values + " (whole sequence of " + frames + " frames with ankles and foot lock, and the stream; latency " + rmr.StitchInfo.LatencyFrames + ")");
        }

        static void Synthesis(Vectors v, Model syn)
        {
            int k = syn.Joints, steps = v.Int("sy.steps");
            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);
            int n = seeds.Length;
            var frames = v.F("sy.frames");
            var placements = v.F("sy.placements");
            var mean = new float[syn.SynthesisInfo.FrameValueCount];
            syn.SynthesisMeanFrame(mean);
            float worst = Worst(mean, new ReadOnlySpan<float>(frames, 0, mean.Length), "synthesis mean frame");
            int values = 0;
            foreach (var frame in new[] { "out", "unity" })
            {
                ZooCoordinateFrame? engine = null;
                if (frame == "unity") engine = ZooCoordinateFrame.Unity;
                using (var runner = new SynthesisRunner(syn, n))
                using (var chars = new SynthesisCharacters(syn, seeds, engine))
                {
                    chars.Start(frames, placements);
                    var b = new PoseBuffer(n, k, 2);
                    var roots = new List<ZooRootMotion>();
                    var rotations = new List<float>();
                    var contacts = new List<byte>();
                    for (int s = 0; s < steps; s++)
                    {
                        chars.Step(runner, 1f, b.Roots, b.Rotations, b.Contacts);
                        Record(b, roots, rotations, contacts);
                    }
                    worst = Math.Max(worst, Worst(Floats(roots.ToArray()), Floats(v.Roots("sy." + frame)), "synthesis " + frame + " roots"));
                    worst = Math.Max(worst, Worst(rotations.ToArray(), v.Rotations("sy." + frame), "synthesis " + frame + " rotations"));
                    worst = Math.Max(worst, WorstBytes(contacts.ToArray(), v.L("sy.out.contacts"), "synthesis contacts"));
                    values += roots.Count * 14 + rotations.Count;
                }
            }
            Console.WriteLine("parity synthesis: worst=" + worst.ToString("G3") + " values=" + values + " (" + n + " characters x " + steps + " frames, model frame and Unity's)");
            var controls = MemoryMarshal.Cast<float, ZooControl>(v.F("ct.controls").AsSpan()).ToArray();
            using (var runner = new ControlRunner(syn, n))
            using (var chars = new ControlCharacters(syn, seeds))
            {
                chars.Start(frames, placements);
                var b = new PoseBuffer(n, k, 2);
                var z = new ZooControl[n];
                var roots = new List<ZooRootMotion>();
                var rotations = new List<float>();
                var contacts = new List<byte>();
                for (int s = 0; s < steps; s++)
                {
                    for (int c = 0; c < n; c++) z[c] = controls[s];
                    chars.Step(runner, z, b.Roots, b.Rotations, b.Contacts);
                    Record(b, roots, rotations, contacts);
                }
                worst = Worst(Floats(roots.ToArray()), Floats(v.Roots("ct.out")), "control roots");
                worst = Math.Max(worst, Worst(rotations.ToArray(), v.Rotations("ct.out"), "control rotations"));
                worst = Math.Max(worst, WorstBytes(contacts.ToArray(), v.L("ct.out.contacts"), "control contacts"));
                Console.WriteLine("parity control: worst=" + worst.ToString("G3") + " values=" + (roots.Count * 14 + rotations.Count) + " (" + n + " characters x " + steps + " frames, a turn half way)");
            }
            Expect(syn.JointNames().SequenceEqual(v.S("sy.names")), "synthesis joint names");
        }

        // Bad calls.

        static int refused, unexpected, disposedTwice;

        /// <summary>Runs a call that must be refused with <typeparamref name="T"/>, status <paramref name="status"/> and a message starting with <paramref name="function"/> and containing <paramref name="needle"/>.</summary>
        static void Refused<T>(string name, ZooStatus status, string function, string needle, Action call) where T : Exception
        {
            try
            {
                call();
                unexpected++;
                Fail("bad call `" + name + "` was not refused");
            }
            catch (T e)
            {
                var z = e as ZooException;
                var d = e as ZooDisposedException;
                var s = z != null ? z.Status : d != null ? d.Status : (ZooStatus)(-1);
                var message = e.Message;
                bool fromRuntime = message.StartsWith(function + ": ", StringComparison.Ordinal) || message.Contains(" is disposed: " + function + ": ");
                if (s != status || !fromRuntime || !message.Contains(needle))
                {
                    unexpected++;
                    Fail("bad call `" + name + "`: " + typeof(T).Name + " " + s + " `" + message + "`, expected " + status + " from " + function + " mentioning `" + needle + "`");
                }
                else refused++;
            }
            catch (Exception e)
            {
                unexpected++;
                Fail("bad call `" + name + "` raised " + e.GetType().Name + ": " + e.Message + " (expected " + typeof(T).Name + ")");
            }
        }

        static void Wrong(string name, string function, string needle, Action call)
        {
            Refused<ZooException>(name, ZooStatus.InvalidArgument, function, needle, call);
        }

        static void Disposed(string name, string function, string needle, Action call)
        {
            Refused<ZooDisposedException>(name, ZooStatus.NullPointer, function, needle, call);
        }

        static void BadCalls(Vectors v, string dir, Model rtn, Model arnn, Model rmr, Model syn)
        {
            const ZooStatus Null = ZooStatus.NullPointer, Load = ZooStatus.LoadFailed, WrongModel = ZooStatus.WrongModel, State = ZooStatus.InvalidState;
            int k = rtn.Joints, n = v.Int("tr.n"), length = v.Int("tr.length");
            var pastRoots = v.Roots("tr.posed.past");
            var pastRot = v.Rotations("tr.posed.past");
            var targetRoots = v.Roots("tr.posed.target");
            var targetRot = v.Rotations("tr.posed.target");
            var nextRoots = v.Roots("tr.posed.next");
            var nextRot = v.Rotations("tr.posed.next");
            var past = v.F("tr.pos.past");
            var target = v.F("tr.pos.target");
            var next = v.F("tr.pos.next");
            var nan = (float[])target.Clone();
            nan[5] = float.NaN;

            // Loading.
            var garbage = Path.Combine(dir, "garbage.onnx");
            File.WriteAllText(garbage, "not a model");
            Refused<ZooException>("load a garbage file", Load, "zoo_model_load", "not an ONNX model", () => Model.Load(garbage));
            Refused<ZooException>("load a missing file", Load, "zoo_model_load", "missing.onnx", () => Model.Load(Path.Combine(dir, "missing.onnx")));
            Refused<ZooException>("load a null path", Null, "zoo_model_load", "`path` is NULL", () => Model.Load(null));

            // A model of another task.
            Refused<ZooException>("transition runner on a keyframes model", WrongModel, "zoo_transition_runner_new", "use zoo_keyframes_*", () => new TransitionRunner(arnn, 1));
            Refused<ZooException>("transition characters on a synthesis model", WrongModel, "zoo_transition_characters_new", "`synthesis` model", () => new TransitionCharacters(syn, 1));
            Refused<ZooException>("keyframes runner on a transition model", WrongModel, "zoo_keyframes_runner_new", "use zoo_transition_*", () => new KeyframesRunner(rtn, 1));
            Refused<ZooException>("stitch stream on a synthesis model", WrongModel, "zoo_stitch_stream_new", "`synthesis` model", () => new StitchStream(syn));
            Refused<ZooException>("synthesis runner on a stitch model", WrongModel, "zoo_synthesis_runner_new", "`stitch` model", () => new SynthesisRunner(rmr, 1));
            Refused<ZooException>("synthesis characters on a transition model", WrongModel, "zoo_synthesis_characters_new", "`transition` model", () => new SynthesisCharacters(rtn, new ulong[] { 1 }));
            Refused<ZooException>("control runner on a transition model", WrongModel, "zoo_control_runner_new", "`transition` model", () => new ControlRunner(rtn, 1));
            Refused<ZooException>("control characters on a keyframes model", WrongModel, "zoo_control_characters_new", "`keyframes` model", () => new ControlCharacters(arnn, new ulong[] { 1 }));
            Refused<ZooException>("transition info of a keyframes model", WrongModel, "zoo_transition_info", "zoo_keyframes_*", () => { var i = arnn.TransitionInfo; });
            Refused<ZooException>("keyframes info of a stitch model", WrongModel, "zoo_keyframes_info", "zoo_stitch_*", () => { var i = rmr.KeyframesInfo; });
            Refused<ZooException>("stitch info of a transition model", WrongModel, "zoo_stitch_info", "zoo_transition_*", () => { var i = rtn.StitchInfo; });
            Refused<ZooException>("synthesis info of a stitch model", WrongModel, "zoo_synthesis_info", "zoo_stitch_*", () => { var i = rmr.SynthesisInfo; });
            Refused<ZooException>("terrain of a synthesis model", WrongModel, "zoo_transition_terrain", "`synthesis` model", () => { int a; float b; rtn.TryGetTerrain(out a, out b); syn.TryGetTerrain(out a, out b); });
            Refused<ZooException>("stitch window of a transition model", WrongModel, "zoo_stitch_set_window", "zoo_transition_*", () => rtn.SetStitchWindow(10, 5));
            Refused<ZooException>("set refine of a stitch model", WrongModel, "zoo_synthesis_set_refine", "zoo_stitch_*", () => rmr.SetSynthesisRefine(false));
            Refused<ZooException>("mean frame of a transition model", WrongModel, "zoo_synthesis_mean_frame", "zoo_transition_*", () => rtn.SynthesisMeanFrame(new float[4]));
            Refused<ZooException>("stitch refine with a transition model", WrongModel, "zoo_stitch_refine", "zoo_transition_*", () => rtn.StitchRefine(new ZooRootMotion[1], new float[4 * k], true, true, new ZooRootMotion[1], new float[4 * k], new byte[4]));

            // Wrong lengths and indices, every buffer of every call.
            using (var runner = new TransitionRunner(rtn, n))
            using (var chars = new TransitionCharacters(rtn, n))
            using (var other = new TransitionCharacters(rtn, n, ZooCoordinateFrame.Unity))
            {
                var b = new PoseBuffer(n, k);
                var poses = new float[n * 3 * k];
                Refused<ZooException>("step before the start", State, "zoo_transition_step_posed", "", () => chars.StepPosed(runner, b.Roots, b.Rotations));
                Wrong("start: past short", "zoo_transition_start", "`past`", () => chars.Start(runner, new ReadOnlySpan<float>(past, 0, past.Length - 1), target, next, length));
                Wrong("start: target short", "zoo_transition_start", "`target`", () => chars.Start(runner, past, new ReadOnlySpan<float>(target, 1, target.Length - 1), next, length));
                Wrong("start: next long", "zoo_transition_start", "`next`", () => chars.Start(runner, past, target, new float[next.Length + 3], length));
                Wrong("start (Unity): target short", "zoo_transition_start", "`target`", () => other.Start(runner, past, new ReadOnlySpan<float>(target, 1, target.Length - 1), next, length));
                Wrong("start: NaN target", "zoo_transition_start", "NaN", () => chars.Start(runner, past, nan, next, length));
                Refused<ZooException>("start: longer than trained", State, "zoo_transition_start", "zoo_transition_allow_beyond_trained", () => chars.Start(runner, past, target, next, length + 1));
                chars.Start(runner, past, target, next, length);
                Wrong("step: poses short", "zoo_transition_step", "`poses`", () => chars.Step(runner, new float[poses.Length - 1]));
                Wrong("step: poses empty", "zoo_transition_step", "`poses`", () => chars.Step(runner, new float[0]));
                Refused<ZooException>("step: poses null", Null, "zoo_transition_step", "`poses` is NULL", () => chars.Step(runner, null));
                Wrong("start posed: past roots not whole frames", "zoo_transition_start_posed", "`past_roots`", () => chars.StartPosed(runner, new ReadOnlySpan<ZooRootMotion>(pastRoots, 0, pastRoots.Length - 1), pastRot, targetRoots, targetRot, nextRoots, nextRot, length));
                Wrong("start posed: past rotations short", "zoo_transition_start_posed", "`past_rotations`", () => chars.StartPosed(runner, pastRoots, new ReadOnlySpan<float>(pastRot, 0, pastRot.Length - 4), targetRoots, targetRot, nextRoots, nextRot, length));
                Wrong("start posed: target rotations short", "zoo_transition_start_posed", "`target_rotations`", () => chars.StartPosed(runner, pastRoots, pastRot, targetRoots, new ReadOnlySpan<float>(targetRot, 0, targetRot.Length - 4), nextRoots, nextRot, length));
                Wrong("start posed (Unity): past rotations not whole", "zoo_transition_start_posed", "`past_rotations`", () => other.StartPosed(runner, pastRoots, new ReadOnlySpan<float>(pastRot, 0, pastRot.Length - 2), targetRoots, targetRot, nextRoots, nextRot, length));
                Wrong("start posed: target roots short", "zoo_transition_start_posed", "`target_roots`", () => chars.StartPosed(runner, pastRoots, pastRot, new ReadOnlySpan<ZooRootMotion>(targetRoots, 0, n - 1), targetRot, nextRoots, nextRot, length));
                Wrong("start posed: next roots long", "zoo_transition_start_posed", "`next_roots`", () => chars.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, new ZooRootMotion[n + 1], nextRot, length));
                Wrong("start posed: next rotations short", "zoo_transition_start_posed", "`next_rotations`", () => chars.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, nextRoots, new ReadOnlySpan<float>(nextRot, 0, nextRot.Length - 4), length));
                Wrong("start posed (Unity): next roots short", "zoo_transition_start_posed", "`next_roots`", () => other.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, new ReadOnlySpan<ZooRootMotion>(nextRoots, 0, n - 1), nextRot, length));
                var nanRot = (float[])targetRot.Clone();
                nanRot[2] = float.NaN;
                Wrong("start posed: NaN rotation", "zoo_transition_start_posed", "NaN", () => chars.StartPosed(runner, pastRoots, pastRot, targetRoots, nanRot, nextRoots, nextRot, length));
                chars.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, nextRoots, nextRot, length);
                Wrong("step posed: roots short", "zoo_transition_step_posed", "`roots`", () => chars.StepPosed(runner, new ZooRootMotion[n - 1], b.Rotations));
                Wrong("step posed: rotations long", "zoo_transition_step_posed", "`rotations`", () => chars.StepPosed(runner, b.Roots, new float[b.Rotations.Length + 4]));
                Wrong("heightmap: heights short", "zoo_transition_set_heightmap", "`heights`", () => chars.SetHeightmap(0, 3, 3, 10f, 0f, 0f, new float[8]));
                Wrong("heightmap: NaN height", "zoo_transition_set_heightmap", "NaN", () => chars.SetHeightmap(0, 2, 1, 10f, 0f, 0f, new[] { 0f, float.NaN }));
                Wrong("heightmap: index out of range", "zoo_transition_set_heightmap", "does not exist", () => chars.SetHeightmap(n, 1, 1, 10f, 0f, 0f, new[] { 0f }));
                Wrong("frames left: index out of range", "zoo_transition_frames_left", "does not exist", () => chars.FramesLeft(n));
                Wrong("frames left: negative index", "zoo_transition_frames_left", "does not exist", () => chars.FramesLeft(-1));
                Wrong("target miss: index out of range", "zoo_transition_target_miss", "does not exist", () => { float a, c; chars.TryGetTargetMiss(7, out a, out c); });
                Wrong("transition characters: count 0", "zoo_transition_characters_new", "`count` is 0", () => new TransitionCharacters(rtn, 0));
                var parents = new int[k];
                var offsets = new float[3 * k];
                Wrong("skeleton: parents short", "zoo_model_skeleton", "`parents`", () => rtn.GetSkeleton(new int[k - 1], offsets));
                Wrong("skeleton: offsets long", "zoo_model_skeleton", "`offsets`", () => rtn.GetSkeleton(parents, new float[3 * k + 1]));
                Wrong("joint name: index out of range", "zoo_model_joint_name", "does not exist", () => rtn.JointName(k));
                Wrong("conversion: rotations not whole", "zoo_pose_convert", "`rotations`", () => rtn.ToEngine(ZooCoordinateFrame.Unity).Poses(b.Roots, new float[6]));
                Wrong("conversion: positions not whole", "zoo_positions_convert", "`positions`", () => rtn.ToEngine(ZooCoordinateFrame.Unity).Positions(new float[4]));
                Wrong("conversion: a frame of 0 metres per unit", "zoo_pose_convert", "metres_per_unit", () => new PoseConversion(rtn.Frame, new ZooCoordinateFrame(0f, ZooUpAxis.Y, ZooHandedness.Left)).Poses(b.Roots, b.Rotations));
            }

            using (var runner = new KeyframesRunner(arnn, 2))
            {
                int d = arnn.KeyframesInfo.FrameValueCount;
                var frames = v.I("kf.frames");
                var counts = v.I("kf.counts");
                var kposes = v.F("kf.poses");
                var outA = new float[40 * d];
                var f4 = frames.Take(4).ToArray();
                var p4 = kposes.Take(4 * d).ToArray();
                Wrong("keyframes: poses short", "zoo_keyframes_complete", "`poses`", () => runner.Complete(f4, new ReadOnlySpan<float>(kposes, 0, 4 * d - 1), ReadOnlySpan<byte>.Empty, outA));
                Wrong("keyframes: out short", "zoo_keyframes_complete", "`out`", () => runner.Complete(f4, p4, ReadOnlySpan<byte>.Empty, new float[39 * d]));
                Wrong("keyframes: fixed of a model without groups", "zoo_keyframes_complete", "fixed", () => runner.Complete(f4, p4, new byte[4], outA));
                Wrong("keyframes: NaN key", "zoo_keyframes_complete", "NaN", () => { var p = (float[])p4.Clone(); p[3] = float.NaN; runner.Complete(f4, p, ReadOnlySpan<byte>.Empty, outA); });
                Wrong("keyframes: frames out of order", "zoo_keyframes_complete", "strictly increas", () => runner.Complete(new[] { 0, 9, 9, 39 }, p4, ReadOnlySpan<byte>.Empty, outA));
                Wrong("keyframes: negative frame", "zoo_keyframes_complete", "", () => runner.Complete(new[] { 0, -9, 24, 39 }, p4, ReadOnlySpan<byte>.Empty, outA));
                var batchOut = new float[71 * d];
                Wrong("keyframes batch: counts do not add up", "zoo_keyframes_complete_batch", "key_counts", () => runner.CompleteBatch(new[] { 4, 2 }, frames, kposes, ReadOnlySpan<byte>.Empty, batchOut));
                Wrong("keyframes batch: out short", "zoo_keyframes_complete_batch", "`out`", () => runner.CompleteBatch(counts, frames, kposes, ReadOnlySpan<byte>.Empty, new float[70 * d]));
                Wrong("keyframes batch: more characters than the runner's batch", "zoo_keyframes_complete_batch", "made for at most 2", () => runner.CompleteBatch(new[] { 4, 3, 4 }, frames.Concat(frames.Take(4)).ToArray(), kposes.Concat(kposes.Take(4 * d)).ToArray(), ReadOnlySpan<byte>.Empty, new float[111 * d]));
            }

            int kr = rmr.Joints;
            var sRoots = v.Roots("st.in");
            var sRot = v.Rotations("st.in");
            int sf = sRoots.Length;
            Wrong("stitch refine: rotations short", "zoo_stitch_refine", "`rotations`", () => rmr.StitchRefine(sRoots, new ReadOnlySpan<float>(sRot, 0, sRot.Length - 4), true, true, new ZooRootMotion[sf], new float[sRot.Length], new byte[4 * sf]));
            Wrong("stitch refine: out roots short", "zoo_stitch_refine", "`out_roots`", () => rmr.StitchRefine(sRoots, sRot, true, true, new ZooRootMotion[sf - 1], new float[sRot.Length], new byte[4 * sf]));
            Wrong("stitch refine: out rotations short", "zoo_stitch_refine", "`out_rotations`", () => rmr.StitchRefine(sRoots, sRot, true, true, new ZooRootMotion[sf], new float[sRot.Length - 1], new byte[4 * sf]));
            Wrong("stitch refine: contacts short", "zoo_stitch_refine", "`contacts`", () => rmr.StitchRefine(sRoots, sRot, true, true, new ZooRootMotion[sf], new float[sRot.Length], new byte[4 * sf - 1]));
            Wrong("stitch refine (Unity): rotations not whole", "zoo_stitch_refine", "`rotations`", () => rmr.StitchRefine(sRoots, new ReadOnlySpan<float>(sRot, 0, sRot.Length - 3), true, true, new ZooRootMotion[sf], new float[sRot.Length], new byte[4 * sf], ZooCoordinateFrame.Unity));
            Wrong("stitch refine at seams: seam past the end", "zoo_stitch_refine_at_seams", "seam at frame", () => rmr.StitchRefineAtSeams(sRoots, sRot, new[] { sf }, true, true, new ZooRootMotion[sf], new float[sRot.Length], new byte[4 * sf]));
            Wrong("stitch refine: shorter than a window", "zoo_stitch_refine", "window", () => rmr.StitchRefine(new ReadOnlySpan<ZooRootMotion>(sRoots, 0, 3), new ReadOnlySpan<float>(sRot, 0, 12 * kr), true, true, new ZooRootMotion[3], new float[12 * kr], new byte[12]));
            using (var stream = new StitchStream(rmr))
            using (var other = new StitchStream(rmr, ZooCoordinateFrame.Unity))
            {
                var root = new ZooRootMotion();
                Wrong("stream push: rotations short", "zoo_stitch_stream_push", "`rotations`", () => stream.Push(sRoots[0], new float[4 * kr - 4]));
                Wrong("stream push (Unity): rotations not whole", "zoo_stitch_stream_push", "`rotations`", () => other.Push(sRoots[0], new float[4 * kr - 1]));
                Wrong("stream push: NaN", "zoo_stitch_stream_push", "NaN", () => { var q = new float[4 * kr]; q[0] = float.NaN; stream.Push(sRoots[0], q); });
                Refused<ZooException>("stream finish: too short", State, "zoo_stitch_stream_finish", "window", () => stream.Finish());
                for (int f = 0; f < sf; f++) stream.Push(sRoots[f], new ReadOnlySpan<float>(sRot, f * 4 * kr, 4 * kr));
                Wrong("stream pop: rotations short", "zoo_stitch_stream_pop", "`rotations`", () => stream.TryPop(ref root, new float[4 * kr - 1], new byte[4]));
                Wrong("stream pop: contacts short", "zoo_stitch_stream_pop", "`contacts`", () => stream.TryPop(ref root, new float[4 * kr], new byte[3]));
                stream.Finish();
                Refused<ZooException>("stream push after finish", State, "zoo_stitch_stream_push", "", () => stream.Push(sRoots[0], new ReadOnlySpan<float>(sRot, 0, 4 * kr)));
                Refused<ZooException>("stream mark seam after finish", State, "zoo_stitch_stream_mark_seam", "finished", () => stream.MarkSeam());
                Refused<ZooException>("stream cleanup after a push", State, "zoo_stitch_stream_set_cleanup", "before its first push", () => stream.SetCleanup(false, false));
                using (var bare = new StitchStream(rmr))
                {
                    bare.SetCleanup(false, false);
                    Expect(bare.Latency == rmr.StitchInfo.LatencyFrames, "without ankle IK and lock the guard keeps the lookahead");
                }
                Refused<ZooException>("stitch window while a stream lives", State, "zoo_stitch_set_window", "", () => rmr.SetStitchWindow(10, 5));
            }

            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);
            int ns = seeds.Length, ks = syn.Joints;
            var sframes = v.F("sy.frames");
            var splace = v.F("sy.placements");
            using (var runner = new SynthesisRunner(syn, ns))
            using (var chars = new SynthesisCharacters(syn, seeds))
            using (var crunner = new ControlRunner(syn, ns))
            using (var cchars = new ControlCharacters(syn, seeds))
            {
                var b = new PoseBuffer(ns, ks, 2);
                Refused<ZooException>("synthesis step before the start", State, "zoo_synthesis_step", "", () => chars.Step(runner, 1f, b.Roots, b.Rotations, b.Contacts));
                Refused<ZooException>("control step before the start", State, "zoo_control_step", "", () => cchars.Step(crunner, new ZooControl[ns], b.Roots, b.Rotations, b.Contacts));
                Wrong("synthesis start: frames short", "zoo_synthesis_start", "`frames`", () => chars.Start(new ReadOnlySpan<float>(sframes, 0, sframes.Length - 1), splace));
                Wrong("synthesis start: placements short", "zoo_synthesis_start", "`placements`", () => chars.Start(sframes, new float[3 * ns - 1]));
                Wrong("synthesis start: NaN frame", "zoo_synthesis_start", "NaN", () => { var f = (float[])sframes.Clone(); f[1] = float.NaN; chars.Start(f, splace); });
                chars.Start(sframes, splace);
                Wrong("synthesis step: roots short", "zoo_synthesis_step", "`roots`", () => chars.Step(runner, 1f, new ZooRootMotion[ns - 1], b.Rotations, b.Contacts));
                Wrong("synthesis step: rotations short", "zoo_synthesis_step", "`rotations`", () => chars.Step(runner, 1f, b.Roots, new float[b.Rotations.Length - 1], b.Contacts));
                Wrong("synthesis step: contacts short", "zoo_synthesis_step", "`contacts`", () => chars.Step(runner, 1f, b.Roots, b.Rotations, new byte[2 * ns - 1]));
                Wrong("synthesis step: NaN temperature", "zoo_synthesis_step", "temperature", () => chars.Step(runner, float.NaN, b.Roots, b.Rotations, b.Contacts));
                Wrong("synthesis characters: no seeds", "zoo_synthesis_characters_new", "`count` is 0", () => new SynthesisCharacters(syn, new ulong[0]));
                Wrong("mean frame: short", "zoo_synthesis_mean_frame", "`frame`", () => syn.SynthesisMeanFrame(new float[3]));
                Wrong("control start: frames not whole", "zoo_control_start", "`frames`", () => cchars.Start(new ReadOnlySpan<float>(sframes, 0, sframes.Length - 1), splace));
                Wrong("control start: placements long", "zoo_control_start", "`placements`", () => cchars.Start(sframes, new float[3 * ns + 3]));
                cchars.Start(sframes, splace);
                var z = new ZooControl[ns];
                Wrong("control step: controls short", "zoo_control_step", "`controls`", () => cchars.Step(crunner, new ZooControl[ns - 1], b.Roots, b.Rotations, b.Contacts));
                Wrong("control step: roots long", "zoo_control_step", "`roots`", () => cchars.Step(crunner, z, new ZooRootMotion[ns + 1], b.Rotations, b.Contacts));
                Wrong("control step: rotations short", "zoo_control_step", "`rotations`", () => cchars.Step(crunner, z, b.Roots, new float[4], b.Contacts));
                Wrong("control step: contacts short", "zoo_control_step", "`contacts`", () => cchars.Step(crunner, z, b.Roots, b.Rotations, new byte[1]));
                Wrong("control step: NaN speed", "zoo_control_step", "speed", () => { var bad = new ZooControl[ns]; bad[1].Speed = float.NaN; cchars.Step(crunner, bad, b.Roots, b.Rotations, b.Contacts); });
                Wrong("control characters: bad settings", "zoo_control_characters_new", "batch", () => { var s = ControlSettings.Default(); s.Batch = 0; new ControlCharacters(syn, seeds, s); });
                Wrong("control characters: empty offsets", "zoo_control_characters_new", "offsets", () => { var s = ControlSettings.Default(); s.SpeedOffsets = new[] { float.NaN }; new ControlCharacters(syn, seeds, s); });
            }

            // Missing bones: refused by the mapping with the list.
            var joints = rtn.JointNames();
            Refused<ZooException>("bone mapping with missing bones", ZooStatus.InvalidArgument, "BoneMapping.Map",
                "no bone for " + (joints.Length - 1) + " of the model's " + joints.Length + " joints: `" + joints[1] + "`, `" + joints[2] + "`",
                () => BoneMapping.Map(joints, new[] { joints[0], "Unrelated" }));
            var renamed = joints.Select(j => "mixamorig:" + j).Reverse().ToArray();
            var renames = joints.ToDictionary(j => j, j => "mixamorig:" + j);
            var mapped = BoneMapping.Map(joints, renamed, renames);
            Expect(mapped.SequenceEqual(Enumerable.Range(0, joints.Length).Select(j => joints.Length - 1 - j)), "a bone map renames: " + string.Join(",", mapped));

            // Disposal: every wrapper disposed twice (the second time refused with a
            // ZooDisposedException naming the wrapper, nothing freed twice), then used: refused
            // with the runtime's NULL message.
            var model = Model.Load(Path.Combine(dir, "rtn.onnx"));
            var tr = new TransitionRunner(model, n);
            var tc = new TransitionCharacters(model, n);
            var kfModel = Model.Load(Path.Combine(dir, "arnn.onnx"));
            var kr2 = new KeyframesRunner(kfModel, 1);
            var stModel = Model.Load(Path.Combine(dir, "rmr.onnx"));
            var ss = new StitchStream(stModel);
            var syModel = Model.Load(Path.Combine(dir, "rnngmm.onnx"));
            var sr = new SynthesisRunner(syModel, 1);
            var sc = new SynthesisCharacters(syModel, new ulong[] { 1 });
            var cr = new ControlRunner(syModel, 1);
            var cc = new ControlCharacters(syModel, new ulong[] { 1 });
            var all = new ZooObject[] { tr, tc, kr2, ss, sr, sc, cr, cc, model, kfModel, stModel, syModel };
            foreach (var o in all)
            {
                o.Dispose();
                var before = refused;
                Refused<ZooDisposedException>("dispose twice: " + o.GetType().Name, ZooStatus.NullPointer, o.GetType().Name + ".Dispose",
                    "is already disposed (it was disposed twice", () => o.Dispose());
                if (refused > before) disposedTwice++;
                Expect(o.IsDisposed, o.GetType().Name + ".IsDisposed");
            }
            using (var liveRunner = new TransitionRunner(rtn, n))
            using (var liveChars = new TransitionCharacters(rtn, n))
            using (var liveSr = new SynthesisRunner(syn, 1))
            using (var liveSc = new SynthesisCharacters(syn, new ulong[] { 1 }))
            using (var liveCr = new ControlRunner(syn, 1))
            using (var liveCc = new ControlCharacters(syn, new ulong[] { 1 }))
            {
                var b = new PoseBuffer(n, k);
                var one = new PoseBuffer(1, syn.Joints, 2);
                Disposed("disposed model: runner", "zoo_transition_runner_new", "`model` is NULL", () => new TransitionRunner(model, 1));
                Disposed("disposed model: characters", "zoo_transition_characters_new", "`model` is NULL", () => new TransitionCharacters(model, 1));
                Disposed("disposed model: info", "zoo_transition_info", "`model` is NULL", () => { var i = model.TransitionInfo; });
                Disposed("disposed model: task", "zoo_model_task", "`model` is NULL", () => model.QueryTask());
                Disposed("disposed model: skeleton", "zoo_model_skeleton", "`model` is NULL", () => model.GetSkeleton(new int[k], new float[3 * k]));
                Disposed("disposed model: joint name", "zoo_model_joint_name", "`model` is NULL", () => model.JointName(0));
                Disposed("disposed model: terrain", "zoo_transition_terrain", "`model` is NULL", () => { int a; float c; model.TryGetTerrain(out a, out c); });
                Disposed("disposed model: keyframes info", "zoo_keyframes_info", "`model` is NULL", () => { var i = kfModel.KeyframesInfo; });
                Disposed("disposed model: keyframes runner", "zoo_keyframes_runner_new", "`model` is NULL", () => new KeyframesRunner(kfModel, 1));
                Disposed("disposed model: stitch info", "zoo_stitch_info", "`model` is NULL", () => { var i = stModel.StitchInfo; });
                Disposed("disposed model: stitch window", "zoo_stitch_set_window", "`model` is NULL", () => stModel.SetStitchWindow(10, 5));
                Disposed("disposed model: stitch refine", "zoo_stitch_refine", "`model` is NULL", () => stModel.StitchRefine(sRoots, sRot, true, true, new ZooRootMotion[sf], new float[sRot.Length], new byte[4 * sf]));
                Disposed("disposed model: stitch stream", "zoo_stitch_stream_new", "`model` is NULL", () => new StitchStream(stModel));
                Disposed("disposed model: synthesis info", "zoo_synthesis_info", "`model` is NULL", () => { var i = syModel.SynthesisInfo; });
                Disposed("disposed model: set refine", "zoo_synthesis_set_refine", "`model` is NULL", () => syModel.SetSynthesisRefine(true));
                Disposed("disposed model: mean frame", "zoo_synthesis_mean_frame", "`model` is NULL", () => syModel.SynthesisMeanFrame(new float[4]));
                Disposed("disposed model: synthesis runner", "zoo_synthesis_runner_new", "`model` is NULL", () => new SynthesisRunner(syModel, 1));
                Disposed("disposed model: synthesis characters", "zoo_synthesis_characters_new", "`model` is NULL", () => new SynthesisCharacters(syModel, new ulong[] { 1 }));
                Disposed("disposed model: control runner", "zoo_control_runner_new", "`model` is NULL", () => new ControlRunner(syModel, 1));
                Disposed("disposed model: control characters", "zoo_control_characters_new", "`model` is NULL", () => new ControlCharacters(syModel, new ulong[] { 1 }));
                Disposed("disposed runner: allow beyond trained", "zoo_transition_allow_beyond_trained", "`runner` is NULL", () => tr.AllowBeyondTrained(true));
                Disposed("disposed runner: start", "zoo_transition_start", "`runner` is NULL", () => liveChars.Start(tr, past, target, next, length));
                Disposed("disposed runner: step posed", "zoo_transition_step_posed", "`runner` is NULL", () => liveChars.StepPosed(tr, b.Roots, b.Rotations));
                Disposed("disposed characters: start posed", "zoo_transition_start_posed", "`characters` is NULL", () => tc.StartPosed(liveRunner, pastRoots, pastRot, targetRoots, targetRot, nextRoots, nextRot, length));
                Disposed("disposed characters: step", "zoo_transition_step", "`characters` is NULL", () => tc.Step(liveRunner, new float[n * 3 * k]));
                Disposed("disposed characters: step posed", "zoo_transition_step_posed", "`characters` is NULL", () => tc.StepPosed(liveRunner, b.Roots, b.Rotations));
                Disposed("disposed characters: heightmap", "zoo_transition_set_heightmap", "`characters` is NULL", () => tc.SetHeightmap(0, 1, 1, 1f, 0f, 0f, new[] { 0f }));
                Disposed("disposed characters: frames left", "zoo_transition_frames_left", "`characters` is NULL", () => tc.FramesLeft(0));
                Disposed("disposed characters: target miss", "zoo_transition_target_miss", "`characters` is NULL", () => { float a, c; tc.TryGetTargetMiss(0, out a, out c); });
                Disposed("disposed keyframes runner: complete", "zoo_keyframes_complete", "`runner` is NULL", () => kr2.Complete(new[] { 0, 5 }, new float[12], ReadOnlySpan<byte>.Empty, new float[36]));
                Disposed("disposed keyframes runner: batch", "zoo_keyframes_complete_batch", "`runner` is NULL", () => kr2.CompleteBatch(new[] { 2 }, new[] { 0, 5 }, new float[12], ReadOnlySpan<byte>.Empty, new float[36]));
                Disposed("disposed stream: push", "zoo_stitch_stream_push", "`stream` is NULL", () => ss.Push(sRoots[0], new ReadOnlySpan<float>(sRot, 0, 4 * kr)));
                Disposed("disposed stream: ready", "zoo_stitch_stream_ready", "`stream` is NULL", () => { var r = ss.Ready; });
                Disposed("disposed stream: pop", "zoo_stitch_stream_pop", "`stream` is NULL", () => { var root = new ZooRootMotion(); ss.TryPop(ref root, new float[4 * kr], new byte[4]); });
                Disposed("disposed stream: finish", "zoo_stitch_stream_finish", "`stream` is NULL", () => ss.Finish());
                Disposed("disposed synthesis characters: start", "zoo_synthesis_start", "`characters` is NULL", () => sc.Start(new ReadOnlySpan<float>(sframes, 0, sframes.Length / ns), new float[3]));
                Disposed("disposed synthesis runner: step", "zoo_synthesis_step", "`runner` is NULL", () => liveSc.Step(sr, 1f, one.Roots, one.Rotations, one.Contacts));
                Disposed("disposed synthesis characters: step", "zoo_synthesis_step", "`characters` is NULL", () => sc.Step(liveSr, 1f, one.Roots, one.Rotations, one.Contacts));
                Disposed("disposed control characters: start", "zoo_control_start", "`characters` is NULL", () => cc.Start(new ReadOnlySpan<float>(sframes, 0, sframes.Length / ns), new float[3]));
                Disposed("disposed control runner: step", "zoo_control_step", "`runner` is NULL", () => liveCc.Step(cr, new ZooControl[1], one.Roots, one.Rotations, one.Contacts));
                Disposed("disposed control characters: step", "zoo_control_step", "`characters` is NULL", () => cc.Step(liveCr, new ZooControl[1], one.Roots, one.Rotations, one.Contacts));
            }

            // Everything still works after the refusals.
            using (var runner = new TransitionRunner(rtn, n))
            using (var chars = new TransitionCharacters(rtn, n))
            {
                var b = new PoseBuffer(n, k);
                chars.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, nextRoots, nextRot, length);
                chars.StepPosed(runner, b.Roots, b.Rotations);
            }
            Console.WriteLine("bad calls: refused=" + refused + " unexpected=" + unexpected + " (each a managed exception with the runtime's status and message, the process alive; "
                + "disposed twice: " + disposedTwice + " wrappers, each second Dispose refused)");
        }

        // Named cases (C ABI 3): each prints `case NAME: passed` or `case NAME: FAILED`.

        static void Case(string name, Action body)
        {
            int before = failures;
            try { body(); }
            catch (Exception e) { Fail(name + ": raised " + e.GetType().Name + ": " + e.Message); }
            Console.WriteLine("case " + name + ": " + (failures == before ? "passed" : "FAILED"));
        }

        /// <summary>A call refused by the runtime with a ZooException of <paramref name="status"/>, its message starting with <paramref name="function"/> and containing <paramref name="needle"/>.</summary>
        static void ByRuntime(string what, ZooStatus status, string function, string needle, Action call)
        {
            try
            {
                call();
                Fail(what + ": not refused");
            }
            catch (ZooException e)
            {
                if (e.Status != status || !e.Message.StartsWith(function + ": ", StringComparison.Ordinal) || !e.Message.Contains(needle))
                    Fail(what + ": ZooException " + e.Status + " `" + e.Message + "`, expected " + status + " from " + function + " mentioning `" + needle + "`");
                else if (!e.StatusName.StartsWith("ZOO_STATUS_", StringComparison.Ordinal) || e.StatusName == "ZOO_STATUS_UNKNOWN")
                    Fail(what + ": StatusName " + e.StatusName);
                else Console.WriteLine("  " + what + ": " + e.StatusName + " `" + e.Message + "`");
            }
            catch (Exception e)
            {
                Fail(what + ": raised " + e.GetType().Name + ": " + e.Message + " (expected a ZooException from the runtime)");
            }
        }

        /// <summary>A call refused before anything reaches the runtime with an ArgumentOutOfRangeException naming <paramref name="parameter"/> and <paramref name="where"/>.</summary>
        static void OutOfRange(string what, string parameter, string where, Action call)
        {
            try
            {
                call();
                Fail(what + ": not refused");
            }
            catch (ArgumentOutOfRangeException e)
            {
                if (e.ParamName != parameter || !e.Message.StartsWith(where + ": ", StringComparison.Ordinal))
                    Fail(what + ": ArgumentOutOfRangeException for `" + e.ParamName + "`: " + e.Message + " (expected `" + parameter + "`, from " + where + ")");
                else Console.WriteLine("  " + what + ": ArgumentOutOfRangeException `" + e.Message.Split('\n')[0] + "`");
            }
            catch (Exception e)
            {
                Fail(what + ": raised " + e.GetType().Name + ": " + e.Message + " (expected an ArgumentOutOfRangeException)");
            }
        }

        /// <summary>A member of a disposed wrapper: a ZooDisposedException (an ObjectDisposedException) naming the wrapper and the member.</summary>
        static void DisposedMember(string what, string type, Action call)
        {
            try
            {
                call();
                Fail(what + ": answered after Dispose");
            }
            catch (ZooDisposedException e)
            {
                if (!(e is ObjectDisposedException) || e.ObjectName != type || !e.Message.Contains(what))
                    Fail(what + ": ZooDisposedException for " + e.ObjectName + ": " + e.Message);
            }
            catch (Exception e)
            {
                Fail(what + ": raised " + e.GetType().Name + ": " + e.Message + " (expected an ObjectDisposedException)");
            }
        }

        static bool SameBits(float[] a, float[] b, string what)
        {
            bool same = a.Length == b.Length && MemoryMarshal.Cast<float, int>(a.AsSpan()).SequenceEqual(MemoryMarshal.Cast<float, int>(b.AsSpan()));
            if (!same) Fail(what + ": the model loaded from bytes gives other outputs than the one loaded from its file (" + a.Length + " and " + b.Length + " values)");
            return same;
        }

        static float[] Concat(List<ZooRootMotion> roots, List<float> rotations, List<byte> contacts)
        {
            var all = new List<float>(Floats(roots.ToArray()).ToArray());
            all.AddRange(rotations);
            if (contacts != null) all.AddRange(contacts.Select(c => (float)c));
            return all.ToArray();
        }

        /// <summary>Everything the transition test computes, in one array: posed and positions, the model's frame and Unity's, target misses.</summary>
        static float[] TransitionOutputs(Vectors v, Model m)
        {
            int n = v.Int("tr.n"), length = v.Int("tr.length"), k = m.Joints;
            var all = new List<float>();
            foreach (var frame in new[] { "posed", "unity" })
                using (var runner = new TransitionRunner(m, n))
                using (var chars = new TransitionCharacters(m, n, frame == "unity" ? ZooCoordinateFrame.Unity : (ZooCoordinateFrame?)null))
                {
                    var p = "tr." + frame;
                    chars.StartPosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length);
                    var b = new PoseBuffer(n, k);
                    var roots = new List<ZooRootMotion>();
                    var rotations = new List<float>();
                    for (int s = 0; s <= length; s++)
                    {
                        chars.StepPosed(runner, b.Roots, b.Rotations);
                        Record(b, roots, rotations, null);
                    }
                    all.AddRange(Concat(roots, rotations, null));
                    for (int c = 0; c < n; c++)
                    {
                        float mean, max;
                        chars.TryGetTargetMiss(c, out mean, out max);
                        all.Add(mean);
                        all.Add(max);
                    }
                }
            foreach (var frame in new[] { "pos", "unity.pos" })
                using (var runner = new TransitionRunner(m, n))
                using (var chars = new TransitionCharacters(m, n, frame == "unity.pos" ? ZooCoordinateFrame.Unity : (ZooCoordinateFrame?)null))
                {
                    var p = "tr." + frame;
                    chars.Start(runner, v.F(p + ".past"), v.F(p + ".target"), v.F(p + ".next"), length);
                    var poses = new float[n * 3 * k];
                    for (int s = 0; s <= length; s++)
                    {
                        chars.Step(runner, poses);
                        all.AddRange(poses);
                    }
                }
            var offsets = new float[3 * k];
            m.GetSkeleton(new int[k], offsets);
            all.AddRange(offsets);
            return all.ToArray();
        }

        static float[] KeyframesOutputs(Vectors v, Model m)
        {
            int d = m.KeyframesInfo.FrameValueCount;
            var counts = v.I("kf.counts");
            var frames = v.I("kf.frames");
            var poses = v.F("kf.poses");
            using (var runner = new KeyframesRunner(m, 2))
            {
                var batch = new float[(frames[counts[0] - 1] + 1 + frames[frames.Length - 1] + 1) * d];
                runner.CompleteBatch(counts, frames, poses, ReadOnlySpan<byte>.Empty, batch);
                var single = new float[(frames[counts[0] - 1] + 1) * d];
                runner.Complete(new ReadOnlySpan<int>(frames, 0, counts[0]), new ReadOnlySpan<float>(poses, 0, counts[0] * d), ReadOnlySpan<byte>.Empty, single);
                return batch.Concat(single).ToArray();
            }
        }

        static float[] StitchOutputs(Vectors v, Model m)
        {
            int k = m.Joints;
            var roots = v.Roots("st.in");
            var rotations = v.Rotations("st.in");
            int frames = roots.Length;
            var outRoots = new ZooRootMotion[frames];
            var outRotations = new float[frames * 4 * k];
            var contacts = new byte[frames * 4];
            m.StitchRefine(roots, rotations, true, true, outRoots, outRotations, contacts);
            var all = new List<float>(Concat(outRoots.ToList(), outRotations.ToList(), contacts.ToList()));
            m.StitchRefineAtSeams(roots, rotations, v.I("st.seams"), true, true, outRoots, outRotations, contacts, ZooCoordinateFrame.Unity);
            all.AddRange(Concat(outRoots.ToList(), outRotations.ToList(), contacts.ToList()));
            using (var stream = new StitchStream(m))
            {
                var popped = new List<ZooRootMotion>();
                var poppedRotations = new List<float>();
                var poppedContacts = new List<byte>();
                var root = new ZooRootMotion();
                var q = new float[4 * k];
                var c = new byte[4];
                for (int f = 0; f <= frames; f++)
                {
                    if (f < frames) stream.Push(roots[f], new ReadOnlySpan<float>(rotations, f * 4 * k, 4 * k));
                    else stream.Finish();
                    while (stream.TryPop(ref root, q, c))
                    {
                        popped.Add(root);
                        poppedRotations.AddRange(q);
                        poppedContacts.AddRange(c);
                    }
                }
                all.AddRange(Concat(popped, poppedRotations, poppedContacts));
            }
            return all.ToArray();
        }

        static float[] SynthesisOutputs(Vectors v, Model m)
        {
            int k = m.Joints, steps = v.Int("sy.steps");
            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);
            int n = seeds.Length;
            var mean = new float[m.SynthesisInfo.FrameValueCount];
            m.SynthesisMeanFrame(mean);
            var all = new List<float>(mean);
            using (var runner = new SynthesisRunner(m, n))
            using (var chars = new SynthesisCharacters(m, seeds, ZooCoordinateFrame.Unity))
            {
                chars.Start(v.F("sy.frames"), v.F("sy.placements"));
                var b = new PoseBuffer(n, k, 2);
                var roots = new List<ZooRootMotion>();
                var rotations = new List<float>();
                var contacts = new List<byte>();
                for (int s = 0; s < steps; s++)
                {
                    chars.Step(runner, 1f, b.Roots, b.Rotations, b.Contacts);
                    Record(b, roots, rotations, contacts);
                }
                all.AddRange(Concat(roots, rotations, contacts));
            }
            return all.ToArray();
        }

        static float[] ControlOutputs(Vectors v, Model m)
        {
            int k = m.Joints, steps = v.Int("sy.steps");
            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);
            int n = seeds.Length;
            var controls = MemoryMarshal.Cast<float, ZooControl>(v.F("ct.controls").AsSpan()).ToArray();
            using (var runner = new ControlRunner(m, n))
            using (var chars = new ControlCharacters(m, seeds))
            {
                chars.Start(v.F("sy.frames"), v.F("sy.placements"));
                var b = new PoseBuffer(n, k, 2);
                var z = new ZooControl[n];
                var roots = new List<ZooRootMotion>();
                var rotations = new List<float>();
                var contacts = new List<byte>();
                for (int s = 0; s < steps; s++)
                {
                    for (int c = 0; c < n; c++) z[c] = controls[s];
                    chars.Step(runner, z, b.Roots, b.Rotations, b.Contacts);
                    Record(b, roots, rotations, contacts);
                }
                return Concat(roots, rotations, contacts);
            }
        }

        /// <summary>The model of <paramref name="file"/> loaded from its bytes gives the outputs of the one loaded from the file, bit for bit.</summary>
        static void FromBytesCase(string dir, string file, Model fromFile, Func<Model, float[]> outputs)
        {
            using (var fromBytes = Model.FromBytes(File.ReadAllBytes(Path.Combine(dir, file))))
            {
                var a = fromFile.Info;
                var b = fromBytes.Info;
                Expect(a.Task == b.Task && a.JointCount == b.JointCount && a.Fps == b.Fps && a.MetresPerUnit == b.MetresPerUnit && a.UpAxis == b.UpAxis
                    && a.Handedness == b.Handedness && a.FormatVersion == b.FormatVersion, file + ": the info differs between the file and its bytes");
                Expect(fromFile.JointNames().SequenceEqual(fromBytes.JointNames()), file + ": the joint names differ between the file and its bytes");
                var x = outputs(fromFile);
                var y = outputs(fromBytes);
                if (SameBits(x, y, file)) Console.WriteLine("  " + file + ": " + x.Length + " output values bit-identical from the file and from its bytes");
            }
        }

        static void Cases(Vectors v, string dir, Model rtn, Model arnn, Model rmr, Model syn)
        {
            const ZooStatus Invalid = ZooStatus.InvalidArgument;
            const int Max = ZooNative.ZOO_MAX_BATCH;
            int k = rtn.Joints, n = v.Int("tr.n"), length = v.Int("tr.length");
            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);

            // Counts: int.MaxValue (above ZOO_MAX_BATCH: refused by the runtime with its message, no
            // allocation, no crash) and negative (refused by the wrapper) for every constructor that
            // takes one.
            Case("count_int_max.transition_runner", () => ByRuntime("new TransitionRunner(model, int.MaxValue)", Invalid, "zoo_transition_runner_new", "`max_batch` is 2147483647, more than ZOO_MAX_BATCH (" + Max + ")", () => new TransitionRunner(rtn, int.MaxValue)));
            Case("count_negative.transition_runner", () => OutOfRange("new TransitionRunner(model, -1)", "maxBatch", "zoo_transition_runner_new", () => new TransitionRunner(rtn, -1)));
            Case("count_int_max.transition_characters", () => ByRuntime("new TransitionCharacters(model, int.MaxValue)", Invalid, "zoo_transition_characters_new", "`count` is 2147483647, more than ZOO_MAX_BATCH", () => new TransitionCharacters(rtn, int.MaxValue)));
            Case("count_negative.transition_characters", () => OutOfRange("new TransitionCharacters(model, -1)", "count", "zoo_transition_characters_new", () => new TransitionCharacters(rtn, -1, ZooCoordinateFrame.Unity)));
            Case("count_int_max.keyframes_runner", () => ByRuntime("new KeyframesRunner(model, int.MaxValue)", Invalid, "zoo_keyframes_runner_new", "`max_batch` is 2147483647, more than ZOO_MAX_BATCH", () => new KeyframesRunner(arnn, int.MaxValue)));
            Case("count_negative.keyframes_runner", () => OutOfRange("new KeyframesRunner(model, -1)", "maxBatch", "zoo_keyframes_runner_new", () => new KeyframesRunner(arnn, -1)));
            Case("count_int_max.synthesis_runner", () => ByRuntime("new SynthesisRunner(model, int.MaxValue)", Invalid, "zoo_synthesis_runner_new", "`max_batch` is 2147483647, more than ZOO_MAX_BATCH", () => new SynthesisRunner(syn, int.MaxValue)));
            Case("count_negative.synthesis_runner", () => OutOfRange("new SynthesisRunner(model, -1)", "maxBatch", "zoo_synthesis_runner_new", () => new SynthesisRunner(syn, -1)));
            Case("count_int_max.control_runner", () => ByRuntime("new ControlRunner(model, int.MaxValue)", Invalid, "zoo_control_runner_new", "`max_batch` is 2147483647, more than ZOO_MAX_BATCH", () => new ControlRunner(syn, int.MaxValue)));
            Case("count_negative.control_runner", () => OutOfRange("new ControlRunner(model, -1)", "maxBatch", "zoo_control_runner_new", () => new ControlRunner(syn, -1)));
            // The characters of synthesis and control take one seed per character: a count above
            // ZOO_MAX_BATCH is ZOO_MAX_BATCH + 1 seeds (never negative, never int.MaxValue).
            Case("count_above_max_batch.synthesis_characters", () => ByRuntime("new SynthesisCharacters(model, ZOO_MAX_BATCH + 1 seeds)", Invalid, "zoo_synthesis_characters_new", "`count` is " + (Max + 1) + ", more than ZOO_MAX_BATCH", () => new SynthesisCharacters(syn, new ulong[Max + 1])));
            Case("count_above_max_batch.control_characters", () => ByRuntime("new ControlCharacters(model, ZOO_MAX_BATCH + 1 seeds)", Invalid, "zoo_control_characters_new", "`count` is " + (Max + 1) + ", more than ZOO_MAX_BATCH", () => new ControlCharacters(syn, new ulong[Max + 1])));
            Case("count_int_max.pose_buffer", () => OutOfRange("new PoseBuffer(int.MaxValue, K)", "count", "PoseBuffer", () => new PoseBuffer(int.MaxValue, k)));
            Case("count_negative.pose_buffer", () =>
            {
                OutOfRange("new PoseBuffer(-1, K)", "count", "PoseBuffer", () => new PoseBuffer(-1, k));
                OutOfRange("new PoseBuffer(1, -1)", "joints", "PoseBuffer", () => new PoseBuffer(1, -1));
                OutOfRange("new PoseBuffer(1, K, -2)", "contactsPerPose", "PoseBuffer", () => new PoseBuffer(1, k, -2));
                OutOfRange("new PoseBuffer(1, int.MaxValue)", "joints", "PoseBuffer", () => new PoseBuffer(1, int.MaxValue));
            });
            // The other counts and sizes a wrapper takes as an int.
            Case("count_negative.other_sizes", () =>
            {
                using (var runner = new TransitionRunner(rtn, n))
                using (var chars = new TransitionCharacters(rtn, n))
                {
                    OutOfRange("TransitionCharacters.Start(length -1)", "length", "zoo_transition_start", () => chars.Start(runner, v.F("tr.pos.past"), v.F("tr.pos.target"), v.F("tr.pos.next"), -1));
                    OutOfRange("TransitionCharacters.StartPosed(length -1)", "length", "zoo_transition_start_posed", () => chars.StartPosed(runner, v.Roots("tr.posed.past"), v.Rotations("tr.posed.past"), v.Roots("tr.posed.target"), v.Rotations("tr.posed.target"), v.Roots("tr.posed.next"), v.Rotations("tr.posed.next"), -1));
                    OutOfRange("TransitionCharacters.SetHeightmap(cols -1)", "cols", "zoo_transition_set_heightmap", () => chars.SetHeightmap(0, -1, 1, 1f, 0f, 0f, new[] { 0f }));
                    OutOfRange("TransitionCharacters.SetHeightmap(rows -3)", "rows", "zoo_transition_set_heightmap", () => chars.SetHeightmap(0, 1, -3, 1f, 0f, 0f, new[] { 0f }));
                }
                OutOfRange("Model.SetStitchWindow(-60, 5)", "window", "zoo_stitch_set_window", () => rmr.SetStitchWindow(-60, 5));
                OutOfRange("Model.SetStitchWindow(60, -5)", "stride", "zoo_stitch_set_window", () => rmr.SetStitchWindow(60, -5));
                using (var runner = new KeyframesRunner(arnn, 2))
                {
                    int d = arnn.KeyframesInfo.FrameValueCount;
                    OutOfRange("KeyframesRunner.CompleteBatch(key count -3)", "keyCounts[1]", "zoo_keyframes_complete_batch", () => runner.CompleteBatch(new[] { 4, -3 }, v.I("kf.frames"), v.F("kf.poses"), ReadOnlySpan<byte>.Empty, new float[71 * d]));
                }
                OutOfRange("new ControlCharacters(settings.Batch -1)", "settings.Batch", "zoo_control_characters_new", () => { var s = ControlSettings.Default(); s.Batch = -1; new ControlCharacters(syn, seeds, s); });
            });
            // A runner's max_batch is a hard limit: a larger batch is refused at its call.
            Case("max_batch_is_a_limit", () =>
            {
                using (var runner = new TransitionRunner(rtn, n - 1))
                using (var chars = new TransitionCharacters(rtn, n))
                    ByRuntime("transition start of " + n + " characters on a runner of max_batch " + (n - 1), Invalid, "zoo_transition_start_posed", "more than the runner's `max_batch` (" + (n - 1) + ")",
                        () => chars.StartPosed(runner, v.Roots("tr.posed.past"), v.Rotations("tr.posed.past"), v.Roots("tr.posed.target"), v.Rotations("tr.posed.target"), v.Roots("tr.posed.next"), v.Rotations("tr.posed.next"), length));
                int ns = seeds.Length;
                var sb = new PoseBuffer(ns, syn.Joints, 2);
                using (var runner = new SynthesisRunner(syn, ns - 1))
                using (var chars = new SynthesisCharacters(syn, seeds))
                {
                    chars.Start(v.F("sy.frames"), v.F("sy.placements"));
                    ByRuntime("synthesis step of " + ns + " characters on a runner of max_batch " + (ns - 1), Invalid, "zoo_synthesis_step", "more than the runner's `max_batch`", () => chars.Step(runner, 1f, sb.Roots, sb.Rotations, sb.Contacts));
                }
                using (var runner = new ControlRunner(syn, 1))
                using (var chars = new ControlCharacters(syn, seeds))
                {
                    chars.Start(v.F("sy.frames"), v.F("sy.placements"));
                    ByRuntime("control step of " + ns + " characters on a runner of max_batch 1", Invalid, "zoo_control_step", "more than the runner's `max_batch` (1)", () => chars.Step(runner, new ZooControl[ns], sb.Roots, sb.Rotations, sb.Contacts));
                }
            });

            // A transition whose context is fed frame by frame (Begin, then Feed per frame) steps
            // the frames Start gives for the same context, bit for bit.
            Case("transition_fed_per_frame", () =>
            {
                var past = v.F("tr.pos.past");
                var target = v.F("tr.pos.target");
                var next = v.F("tr.pos.next");
                int d = 3 * k, frames = past.Length / (n * d);
                using (var runner = new TransitionRunner(rtn, n))
                using (var a = new TransitionCharacters(rtn, n))
                using (var b = new TransitionCharacters(rtn, n))
                {
                    a.Start(runner, past, target, next, length);
                    var frame = new float[n * d];
                    for (int f = 0; f < frames; f++)
                    {
                        for (int c = 0; c < n; c++)
                            Array.Copy(past, (c * frames + f) * d, frame, c * d, d);
                        if (f == 0) b.Begin(runner, frame, target, next, frames, length);
                        else b.Feed(runner, frame);
                    }
                    var pa = new float[n * d];
                    var pb = new float[n * d];
                    for (int i = 0; i <= length; i++)
                    {
                        a.Step(runner, pa);
                        b.Step(runner, pb);
                        for (int j = 0; j < pa.Length; j++)
                            if (BitConverter.SingleToInt32Bits(pa[j]) != BitConverter.SingleToInt32Bits(pb[j]))
                                throw new Exception("frame " + i + " value " + j + " of the fed transition differs from the started one");
                    }
                }
            });

            // A whole posed transition (GeneratePosed) without the fallback and the lock is the
            // one StartPosed and StepPosed give (up to the rounding of tract's batched kernels: a
            // whole transition runs its graph passes in other batches than stepping); with them it
            // runs and is finite.
            Case("transition_generate_posed", () =>
            {
                var p = "tr.posed";
                using (var runner = new TransitionRunner(rtn, n))
                using (var a = new TransitionCharacters(rtn, n))
                using (var b = new TransitionCharacters(rtn, n))
                {
                    var outRoots = new ZooRootMotion[n * (length + 1)];
                    var outRotations = new float[n * (length + 1) * 4 * k];
                    a.GeneratePosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length, false, false, outRoots, outRotations);
                    b.StartPosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length);
                    var buf = new PoseBuffer(n, k);
                    for (int f = 0; f <= length; f++)
                    {
                        b.StepPosed(runner, buf.Roots, buf.Rotations);
                        for (int c = 0; c < n; c++)
                        {
                            int at = c * (length + 1) + f;
                            var g = outRoots[at].RootPosition;
                            var st = buf.Roots[c].RootPosition;
                            Expect(Math.Abs(g.X - st.X) + Math.Abs(g.Y - st.Y) + Math.Abs(g.Z - st.Z) < 1e-3f, "frame " + f + " character " + c + ": the generated root differs from the stepped one");
                            for (int j = 0; j < 4 * k; j++)
                                if (Math.Abs(outRotations[at * 4 * k + j] - buf.Rotations[c * 4 * k + j]) > 1e-4f)
                                    throw new Exception("frame " + f + " character " + c + " rotation value " + j + " differs from the stepped one");
                        }
                    }
                    a.GeneratePosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length, true, true, outRoots, outRotations);
                    foreach (var x in outRotations)
                        Expect(!float.IsNaN(x) && !float.IsInfinity(x), "a generated rotation is not finite");
                    ByRuntime("GeneratePosed with one root too few", Invalid, "zoo_transition_generate_posed", "`out_roots`", () => a.GeneratePosed(runner, v.Roots(p + ".past"), v.Rotations(p + ".past"), v.Roots(p + ".target"), v.Rotations(p + ".target"),
                        v.Roots(p + ".next"), v.Rotations(p + ".next"), length, true, false, new ZooRootMotion[n * (length + 1) - 1], outRotations));
                }
            });

            // Coordinate frames: the axis and handedness are integers, a value outside the enum is
            // refused by the runtime by its field's name.
            Case("frame_bad_up_axis", () =>
            {
                var bad = new ZooCoordinateFrame(1f, (ZooUpAxis)7, ZooHandedness.Left);
                Expect(bad.UpAxis == 7u && bad.Up == (ZooUpAxis)7, "the frame keeps the value 7");
                var roots = new ZooRootMotion[1];
                roots[0].RootRotation = ZooFloat4.Identity;
                ByRuntime("PoseConversion from a frame with up axis 7", Invalid, "zoo_pose_convert", "`from.up_axis` is 7, not a ZooUpAxis", () => new PoseConversion(bad, rtn.Frame).Poses(roots, new float[] { 0f, 0f, 0f, 1f }));
                ByRuntime("PoseConversion to a frame with up axis 7", Invalid, "zoo_positions_convert", "`to.up_axis` is 7", () => rtn.ToEngine(bad).Positions(new float[3]));
                using (var runner = new TransitionRunner(rtn, n))
                using (var chars = new TransitionCharacters(rtn, n, bad))
                    ByRuntime("TransitionCharacters in a frame with up axis 7", Invalid, "zoo_positions_convert", "`from.up_axis` is 7", () => chars.Start(runner, v.F("tr.pos.past"), v.F("tr.pos.target"), v.F("tr.pos.next"), length));
            });
            Case("frame_bad_handedness", () =>
            {
                var bad = new ZooCoordinateFrame(1f, ZooUpAxis.Y, (ZooHandedness)2);
                ByRuntime("PoseConversion to a frame with handedness 2", Invalid, "zoo_pose_convert", "`to.handedness` is 2, not a ZooHandedness", () => rtn.ToEngine(bad).Rotation(ZooFloat4.Identity));
            });
            Case("frame_enum_values", () =>
            {
                var f = new ZooCoordinateFrame(0.01f, ZooUpAxis.Z, ZooHandedness.Left);
                Expect(f.UpAxis == 1u && f.Handedness == 1u && f.Up == ZooUpAxis.Z && f.Hand == ZooHandedness.Left, "ZooCoordinateFrame(0.01, Z, Left): " + f);
                f.Up = ZooUpAxis.Y;
                f.Hand = ZooHandedness.Right;
                Expect(f.UpAxis == 0u && f.Handedness == 0u, "Up = Y, Hand = Right: " + f.UpAxis + " " + f.Handedness);
                Expect(ZooCoordinateFrame.Unity.Up == ZooUpAxis.Y && ZooCoordinateFrame.Unity.Hand == ZooHandedness.Left, "Unity's frame: " + ZooCoordinateFrame.Unity);
                Expect(rtn.Frame.Up == rtn.Info.UpAxis && rtn.Frame.Hand == rtn.Info.Handedness, "the model's frame: " + rtn.Frame);
                Expect(ZooCoordinateFrame.Unity.ToString() == "1 m/unit, Y up, Left-handed", "ToString: " + ZooCoordinateFrame.Unity);
            });

            // Loading from memory: the same model, bit for bit.
            Case("from_bytes.transition", () => FromBytesCase(dir, "rtn.onnx", rtn, m => TransitionOutputs(v, m)));
            Case("from_bytes.keyframes", () => FromBytesCase(dir, "arnn.onnx", arnn, m => KeyframesOutputs(v, m)));
            Case("from_bytes.stitch", () => FromBytesCase(dir, "rmr.onnx", rmr, m => StitchOutputs(v, m)));
            Case("from_bytes.synthesis", () => FromBytesCase(dir, "rnngmm.onnx", syn, m => SynthesisOutputs(v, m)));
            Case("from_bytes.control", () => FromBytesCase(dir, "rnngmm.onnx", syn, m => ControlOutputs(v, m)));
            Case("from_bytes.refused", () =>
            {
                ByRuntime("Model.FromBytes(null)", ZooStatus.NullPointer, "zoo_model_load_memory", "`bytes` is NULL", () => Model.FromBytes(null));
                ByRuntime("Model.FromBytes(empty)", ZooStatus.LoadFailed, "zoo_model_load_memory", "`bytes_len` is 0", () => Model.FromBytes(new byte[0]));
                ByRuntime("Model.FromBytes(garbage)", ZooStatus.LoadFailed, "zoo_model_load_memory", "the model in memory", () => Model.FromBytes(Encoding.UTF8.GetBytes("not a model")));
                var bytes = File.ReadAllBytes(Path.Combine(dir, "rtn.onnx"));
                ByRuntime("Model.FromBytes(truncated)", ZooStatus.LoadFailed, "zoo_model_load_memory", "", () => Model.FromBytes(bytes.Take(bytes.Length / 2).ToArray()));
            });

            // The library: version, status names, last error, log callback.
            Case("library_version", () =>
            {
                var version = Zoo.Library.Version;
                Console.WriteLine("  Library.Version: " + version);
                Expect(System.Text.RegularExpressions.Regex.IsMatch(version, @"^zoo \d+\.\d+\.\d+\S* \(C ABI 3\)$"), "Library.Version `" + version + "` is not `zoo X.Y.Z (C ABI 3)`");
                Expect(Zoo.Library.AbiVersion == ZooNative.ZOO_ABI_VERSION, "Library.AbiVersion " + Zoo.Library.AbiVersion);
            });
            Case("library_status_names", () =>
            {
                Expect(Zoo.Library.StatusName(ZooStatus.Ok) == "ZOO_STATUS_OK", "StatusName(Ok): " + Zoo.Library.StatusName(ZooStatus.Ok));
                Expect(Zoo.Library.StatusName(ZooStatus.InvalidArgument) == "ZOO_STATUS_INVALID_ARGUMENT", "StatusName(InvalidArgument): " + Zoo.Library.StatusName(ZooStatus.InvalidArgument));
                Expect(Zoo.Library.StatusName((ZooStatus)99) == "ZOO_STATUS_UNKNOWN", "StatusName(99): " + Zoo.Library.StatusName((ZooStatus)99));
                try { new TransitionCharacters(rtn, 0); Fail("count 0 was not refused"); }
                catch (ZooException e)
                {
                    Expect(e.StatusName == "ZOO_STATUS_INVALID_ARGUMENT", "ZooException.StatusName: " + e.StatusName);
                    Expect(e.ToString().StartsWith("Zoo.ZooException (ZOO_STATUS_INVALID_ARGUMENT): zoo_transition_characters_new: ", StringComparison.Ordinal), "ZooException.ToString: " + e.ToString().Split('\n')[0]);
                }
            });
            Case("library_last_error_empty_after_success", () =>
            {
                try { rtn.JointName(k); } catch (ZooException) { }
                Expect(ZooNative.zoo_last_error(null, UIntPtr.Zero).ToUInt64() > 0, "a refused call leaves a message");
                rtn.JointName(0);
                Expect(ZooNative.zoo_last_error(null, UIntPtr.Zero).ToUInt64() == 0, "zoo_last_error is not empty after a successful call");
            });
            Case("library_log_callback", () =>
            {
                var messages = new List<string>();
                Zoo.Library.SetLogCallback((level, message) => { lock (messages) messages.Add(level + " " + message); }, ZooLogLevel.Debug);
                try
                {
                    using (var m = Model.FromBytes(File.ReadAllBytes(Path.Combine(dir, "rtn.onnx"))))
                    using (var runner = new TransitionRunner(m, 1))
                    {
                    }
                    GC.Collect();
                    GC.WaitForPendingFinalizers();
                    using (var m = Model.Load(Path.Combine(dir, "arnn.onnx"))) { }
                }
                finally { Zoo.Library.SetLogCallback(null); }
                Console.WriteLine("  log messages up to Debug while loading two models (the delegate kept alive over a GC): " + messages.Count + (messages.Count > 0 ? ", e.g. `" + messages[0] + "`" : ""));
                ByRuntime("SetLogCallback at level 9", Invalid, "zoo_set_log_callback", "max_level", () => Zoo.Library.SetLogCallback((l, m) => { }, (ZooLogLevel)9));
                Zoo.Library.SetLogCallback((level, message) => { throw new InvalidOperationException("a handler that throws"); }, ZooLogLevel.Debug);
                try { using (var m = Model.Load(Path.Combine(dir, "rtn.onnx"))) { } }
                finally { Zoo.Library.SetLogCallback(null); }
            });

            // Disposal: what a wrapper answers without a native call checks for it too.
            Case("disposed_properties", () =>
            {
                var m = Model.Load(Path.Combine(dir, "rtn.onnx"));
                var tc = new TransitionCharacters(m, n);
                var sm = Model.Load(Path.Combine(dir, "rnngmm.onnx"));
                var sc = new SynthesisCharacters(sm, seeds);
                var cc = new ControlCharacters(sm, seeds);
                var st = new StitchStream(rmr);
                foreach (var o in new ZooObject[] { m, tc, sm, sc, cc, st }) o.Dispose();
                DisposedMember("Info", "Model", () => { var x = m.Info; });
                DisposedMember("Task", "Model", () => { var x = m.Task; });
                DisposedMember("Joints", "Model", () => { var x = m.Joints; });
                DisposedMember("Fps", "Model", () => { var x = m.Fps; });
                DisposedMember("Frame", "Model", () => { var x = m.Frame; });
                DisposedMember("ToEngine", "Model", () => m.ToEngine(ZooCoordinateFrame.Unity));
                DisposedMember("Count", "TransitionCharacters", () => { var x = tc.Count; });
                DisposedMember("Joints", "TransitionCharacters", () => { var x = tc.Joints; });
                DisposedMember("Count", "SynthesisCharacters", () => { var x = sc.Count; });
                DisposedMember("Count", "ControlCharacters", () => { var x = cc.Count; });
                DisposedMember("Latency", "StitchStream", () => { var x = st.Latency; });
            });
        }

        // Managed allocation per step.

        static long Measure(string what, int steps, Action<int> step, StringBuilder report)
        {
            for (int i = 0; i < 20; i++) step(i);
            long before = GC.GetAllocatedBytesForCurrentThread();
            for (int i = 0; i < steps; i++) step(i);
            long bytes = GC.GetAllocatedBytesForCurrentThread() - before;
            report.Append(what).Append(' ').Append(bytes).Append(", ");
            if (bytes != 0) Fail(what + ": " + bytes + " managed bytes allocated over " + steps + " steps");
            return bytes;
        }

        static void Allocation(Vectors v, Model rtn, Model arnn, Model rmr, Model syn)
        {
            const int Steps = 1000;
            long total = 0;
            var report = new StringBuilder();
            int k = rtn.Joints, n = v.Int("tr.n"), length = v.Int("tr.length");
            var pastRoots = v.Roots("tr.unity.past");
            var pastRot = v.Rotations("tr.unity.past");
            var targetRoots = v.Roots("tr.unity.target");
            var targetRot = v.Rotations("tr.unity.target");
            var nextRoots = v.Roots("tr.unity.next");
            var nextRot = v.Rotations("tr.unity.next");
            using (var runner = new TransitionRunner(rtn, n))
            using (var chars = new TransitionCharacters(rtn, n, ZooCoordinateFrame.Unity))
            {
                var b = new PoseBuffer(n, k);
                total += Measure("transition step posed (Unity frame, restarted when done)", Steps, i =>
                {
                    if (i == 0 || chars.FramesLeft(0) == 0) chars.StartPosed(runner, pastRoots, pastRot, targetRoots, targetRot, nextRoots, nextRot, length);
                    chars.StepPosed(runner, b.Roots, b.Rotations);
                }, report);
                var past = v.F("tr.unity.pos.past");
                var target = v.F("tr.unity.pos.target");
                var next = v.F("tr.unity.pos.next");
                var poses = new float[n * 3 * k];
                total += Measure("transition step positions (Unity frame)", Steps, i =>
                {
                    if (i == 0 || chars.FramesLeft(0) == 0) chars.Start(runner, past, target, next, length);
                    chars.Step(runner, poses);
                }, report);
            }
            var seeds = Array.ConvertAll(v.L("sy.seeds"), s => (ulong)s);
            var frames = v.F("sy.frames");
            var placements = v.F("sy.placements");
            using (var runner = new SynthesisRunner(syn, seeds.Length))
            using (var chars = new SynthesisCharacters(syn, seeds, ZooCoordinateFrame.Unity))
            using (var crunner = new ControlRunner(syn, seeds.Length))
            using (var cchars = new ControlCharacters(syn, seeds, null, ZooCoordinateFrame.Unity))
            {
                chars.Start(frames, placements);
                cchars.Start(frames, placements);
                var b = new PoseBuffer(seeds.Length, syn.Joints, 2);
                var z = new ZooControl[seeds.Length];
                for (int c = 0; c < z.Length; c++) z[c] = new ZooControl(150f, 0.5f * c);
                total += Measure("synthesis step (Unity frame)", Steps, i => chars.Step(runner, 1f, b.Roots, b.Rotations, b.Contacts), report);
                total += Measure("control step (Unity frame)", Steps, i => cchars.Step(crunner, z, b.Roots, b.Rotations, b.Contacts), report);
            }
            var sRoots = v.Roots("st.in");
            var sRot = v.Rotations("st.in");
            int kr = rmr.Joints;
            using (var stream = new StitchStream(rmr, ZooCoordinateFrame.Unity))
            {
                var root = new ZooRootMotion();
                var q = new float[4 * kr];
                var c = new byte[4];
                total += Measure("stitch stream push + pop (Unity frame)", Steps, i =>
                {
                    int f = i % sRoots.Length;
                    stream.Push(sRoots[f], new ReadOnlySpan<float>(sRot, f * 4 * kr, 4 * kr));
                    while (stream.Ready) stream.TryPop(ref root, q, c);
                }, report);
            }
            using (var runner = new KeyframesRunner(arnn, 2))
            {
                int d = arnn.KeyframesInfo.FrameValueCount;
                var counts = v.I("kf.counts");
                var kf = v.I("kf.frames");
                var kp = v.F("kf.poses");
                var output = new float[71 * d];
                total += Measure("keyframes complete batch", Steps, i => runner.CompleteBatch(counts, kf, kp, ReadOnlySpan<byte>.Empty, output), report);
            }
            Console.WriteLine("allocation: bytes=" + total + " (GC.GetAllocatedBytesForCurrentThread over " + Steps + " calls each: " + report.ToString().TrimEnd(',', ' ') + ")");
        }

        // Per-frame cost: C# wrappers against the C ABI called from C, same process, interleaved.

        [DllImport("zoo_cbench", CallingConvention = CallingConvention.Cdecl)]
        static extern IntPtr zoo_cbench_new(byte* path, UIntPtr batch, ZooRootMotion* pastRoots, UIntPtr pastRootsLen, float* pastRotations, UIntPtr pastRotationsLen,
            ZooRootMotion* targetRoots, float* targetRotations, ZooRootMotion* nextRoots, float* nextRotations, UIntPtr rotationsLen, UIntPtr length, ZooCoordinateFrame* engine);

        [DllImport("zoo_cbench", CallingConvention = CallingConvention.Cdecl)]
        static extern double zoo_cbench_transition(IntPtr bench);

        [DllImport("zoo_cbench", CallingConvention = CallingConvention.Cdecl)]
        static extern void zoo_cbench_free(IntPtr bench);

        /// <summary>Inputs of <paramref name="batch"/> characters, character c taking character c % 2's poses of the vectors.</summary>
        static void Tile(ZooRootMotion[] roots, float[] rotations, int perCharacter, int have, int batch, int k, out ZooRootMotion[] outRoots, out float[] outRotations)
        {
            outRoots = new ZooRootMotion[batch * perCharacter];
            outRotations = new float[batch * perCharacter * 4 * k];
            for (int c = 0; c < batch; c++)
            {
                Array.Copy(roots, (c % have) * perCharacter, outRoots, c * perCharacter, perCharacter);
                Array.Copy(rotations, (c % have) * perCharacter * 4 * k, outRotations, c * perCharacter * 4 * k, perCharacter * 4 * k);
            }
        }

        static double Median(List<double> values)
        {
            var s = values.OrderBy(x => x).ToList();
            return s[s.Count / 2];
        }

        /// <summary>
        /// The per-frame cost of posed transitions through the C# wrappers and through the C ABI
        /// called from C (cbench.c), batch 1 and 64, in Unity's frame (the C side converting with
        /// zoo_pose_convert as the wrapper does) and in the model's: 11 rounds, each alternating C and
        /// C# transition by transition (who goes first alternates too), timing only the step calls;
        /// the ratio of the medians of the rounds' per-frame times.
        /// </summary>
        static void Timing(Vectors v, string path, Model rtn)
        {
            var utf8 = Encoding.UTF8.GetBytes(path + "\0");
            foreach (var batch in new[] { 1, 64 })
            {
                // On a machine shared with other work a burst can skew one measurement: one beyond
                // 10% is measured again, at most twice, and the line says how many were needed.
                string line = null;
                int attempt;
                for (attempt = 1; attempt <= 3; attempt++)
                {
                    double ratio;
                    line = TimingLine(v, utf8, rtn, batch, out ratio);
                    if (Math.Abs(ratio - 1) <= 0.1) break;
                }
                Console.WriteLine(line + "; attempts=" + Math.Min(attempt, 3));
            }
        }

        /// <summary>One measurement of <see cref="Timing"/> for a batch: the summary line and the Unity-frame ratio.</summary>
        static string TimingLine(Vectors v, byte[] utf8, Model rtn, int batch, out double unityRatio)
        {
            const int Rounds = 11;
            int k = rtn.Joints, have = v.Int("tr.n"), length = v.Int("tr.length");
            int pastFrames = v.Roots("tr.posed.past").Length / have;
            unityRatio = 0;
            {
                int transitions = batch == 1 ? 12 : 5;
                var line = new StringBuilder("timing batch " + batch + ": ");
                foreach (var inUnity in new[] { true, false })
                {
                    var p = inUnity ? "tr.unity" : "tr.posed";
                    ZooRootMotion[] pr, tr, nr;
                    float[] pq, tq, nq;
                    // Both sides get the same inputs, in the engine frame timed (C converting them
                    // to the model's at its start as the wrapper does).
                    Tile(v.Roots(p + ".past"), v.Rotations(p + ".past"), pastFrames, have, batch, k, out pr, out pq);
                    Tile(v.Roots(p + ".target"), v.Rotations(p + ".target"), 1, have, batch, k, out tr, out tq);
                    Tile(v.Roots(p + ".next"), v.Rotations(p + ".next"), 1, have, batch, k, out nr, out nq);
                    ZooCoordinateFrame? engine = null;
                    if (inUnity) engine = ZooCoordinateFrame.Unity;
                    var unity = ZooCoordinateFrame.Unity;
                    IntPtr bench;
                    fixed (byte* pp = utf8)
                    fixed (ZooRootMotion* a = pr)
                    fixed (float* aq = pq)
                    fixed (ZooRootMotion* t = tr)
                    fixed (float* tqq = tq)
                    fixed (ZooRootMotion* x = nr)
                    fixed (float* xq = nq)
                        bench = zoo_cbench_new(pp, (UIntPtr)batch, a, (UIntPtr)pr.Length, aq, (UIntPtr)pq.Length, t, tqq, x, xq, (UIntPtr)tq.Length, (UIntPtr)length, inUnity ? &unity : null);
                    if (bench == IntPtr.Zero) throw new InvalidOperationException("zoo_cbench_new failed: " + Errors());
                    var cTimes = new List<double>();
                    var csTimes = new List<double>();
                    try
                    {
                        using (var runner = new TransitionRunner(rtn, batch))
                        using (var chars = new TransitionCharacters(rtn, batch, engine))
                        {
                            var b = new PoseBuffer(batch, k);
                            Func<double> csharp = () =>
                            {
                                chars.StartPosed(runner, pr, pq, tr, tq, nr, nq, length);
                                long start = Stopwatch.GetTimestamp();
                                for (int s = 0; s <= length; s++) chars.StepPosed(runner, b.Roots, b.Rotations);
                                return (double)(Stopwatch.GetTimestamp() - start) / Stopwatch.Frequency;
                            };
                            Func<double> c = () =>
                            {
                                var seconds = zoo_cbench_transition(bench);
                                if (seconds < 0) throw new InvalidOperationException("the C timing failed with status " + (-seconds - 1) + ": " + Errors());
                                return seconds;
                            };
                            csharp();
                            c();
                            for (int r = 0; r < Rounds; r++)
                            {
                                double sc = 0, scs = 0;
                                for (int i = 0; i < transitions; i++)
                                {
                                    if ((r + i) % 2 == 0) { sc += c(); scs += csharp(); }
                                    else { scs += csharp(); sc += c(); }
                                }
                                cTimes.Add(sc / (transitions * (length + 1)));
                                csTimes.Add(scs / (transitions * (length + 1)));
                            }
                        }
                    }
                    finally { zoo_cbench_free(bench); }
                    double mc = Median(cTimes), mcs = Median(csTimes);
                    if (inUnity) unityRatio = mcs / mc;
                    line.Append(string.Format(System.Globalization.CultureInfo.InvariantCulture, "{0}={1:F3} (C# {2:F1} us, C {3:F1} us per frame) ",
                        inUnity ? "ratio" : "model_frame_ratio", mcs / mc, mcs * 1e6, mc * 1e6));
                }
                line.Append("; C# / C per frame, " + TimingNote + ", medians of " + Rounds + " rounds of " + transitions + " interleaved transitions of " + (length + 1) + " frames each side");
                return line.ToString();
            }
        }

        const string TimingNote = "ratio: poses in Unity's frame (C converting with zoo_pose_convert), model_frame_ratio: in the model's";

        static string Errors()
        {
            var n = (int)ZooNative.zoo_last_error(null, UIntPtr.Zero).ToUInt64();
            var bytes = new byte[n + 1];
            fixed (byte* b = bytes) ZooNative.zoo_last_error(b, (UIntPtr)(ulong)bytes.Length);
            return Encoding.UTF8.GetString(bytes, 0, n);
        }
    }
}
