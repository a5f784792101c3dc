// Handles, lifetimes and errors of the safe wrappers: every wrapper object owns one ZooSafeHandle
// (freed exactly once, by Dispose or by the finalizer), enters it for the length of each native
// call (so another thread's Dispose cannot free it during the call), and turns a status other
// than ZOO_STATUS_OK into an exception carrying zoo_last_error's message. A disposed handle is
// passed to the runtime as NULL, which refuses it with its own message; the wrapper then throws
// ZooDisposedException (an ObjectDisposedException) with that message. What a wrapper answers
// without a native call (a model's cached info, a batch's count) checks for disposal itself. A
// negative count or size is refused with an ArgumentOutOfRangeException before anything is
// allocated (C's size_t has no negative values); a count the runtime cannot take (above
// ZOO_MAX_BATCH) is passed on and refused by the runtime with its message.
using System;
using System.Runtime.InteropServices;
using System.Text;
using Zoo.Native;

namespace Zoo
{
    /// <summary>A call the runtime refused: <see cref="Status"/> and the runtime's message (<c>zoo_last_error</c>), which starts with the C function's name.</summary>
    public class ZooException : Exception
    {
        /// <summary>The status the C function returned.</summary>
        public ZooStatus Status { get; private set; }

        /// <summary>An exception with the runtime's status and message.</summary>
        public ZooException(ZooStatus status, string message) : base(message)
        {
            Status = status;
        }

        /// <summary>The status's C name, e.g. <c>ZOO_STATUS_INVALID_ARGUMENT</c> (<see cref="Library.StatusName"/>).</summary>
        public string StatusName { get { return Library.StatusName(Status); } }

        /// <summary>The exception with its status's C name: <c>Zoo.ZooException (ZOO_STATUS_INVALID_ARGUMENT): zoo_...: ...</c> and the stack trace.</summary>
        public override string ToString()
        {
            var text = base.ToString();
            var type = GetType().FullName;
            return text.StartsWith(type, StringComparison.Ordinal) ? type + " (" + StatusName + ")" + text.Substring(type.Length) : text;
        }
    }

    /// <summary>A call on a disposed wrapper: the runtime refused its NULL handle with <see cref="Status"/> (<c>ZOO_STATUS_NULL_POINTER</c>) and the message in <see cref="Exception.Message"/>.</summary>
    public sealed class ZooDisposedException : ObjectDisposedException
    {
        /// <summary>The status the C function returned.</summary>
        public ZooStatus Status { get; private set; }

        /// <summary>An exception naming the disposed object, with the runtime's status and message.</summary>
        public ZooDisposedException(string objectName, ZooStatus status, string message) : base(objectName, message)
        {
            Status = status;
        }
    }

    /// <summary>What a <see cref="ZooSafeHandle"/> holds, and so which <c>zoo_*_free</c> frees it.</summary>
    internal enum HandleKind
    {
        Model,
        TransitionRunner,
        TransitionCharacters,
        KeyframesRunner,
        StitchStream,
        SynthesisRunner,
        SynthesisCharacters,
        ControlRunner,
        ControlCharacters,
    }

    /// <summary>A pointer from a <c>zoo_*_new</c> or <c>zoo_model_load</c>, freed once with its <c>zoo_*_free</c>.</summary>
    internal sealed unsafe class ZooSafeHandle : SafeHandle
    {
        readonly HandleKind kind;

        internal ZooSafeHandle(HandleKind kind) : base(IntPtr.Zero, true)
        {
            this.kind = kind;
        }

        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }

        internal void Set(IntPtr pointer)
        {
            SetHandle(pointer);
        }

        protected override bool ReleaseHandle()
        {
            switch (kind)
            {
                case HandleKind.Model: ZooNative.zoo_model_free((Native.ZooModel*)handle); break;
                case HandleKind.TransitionRunner: ZooNative.zoo_transition_runner_free((Native.ZooTransitionRunner*)handle); break;
                case HandleKind.TransitionCharacters: ZooNative.zoo_transition_characters_free((Native.ZooTransitionCharacters*)handle); break;
                case HandleKind.KeyframesRunner: ZooNative.zoo_keyframes_runner_free((Native.ZooKeyframesRunner*)handle); break;
                case HandleKind.StitchStream: ZooNative.zoo_stitch_stream_free((Native.ZooStitchStream*)handle); break;
                case HandleKind.SynthesisRunner: ZooNative.zoo_synthesis_runner_free((Native.ZooSynthesisRunner*)handle); break;
                case HandleKind.SynthesisCharacters: ZooNative.zoo_synthesis_characters_free((Native.ZooSynthesisCharacters*)handle); break;
                case HandleKind.ControlRunner: ZooNative.zoo_control_runner_free((Native.ZooControlRunner*)handle); break;
                case HandleKind.ControlCharacters: ZooNative.zoo_control_characters_free((Native.ZooControlCharacters*)handle); break;
            }
            return true;
        }
    }

    /// <summary>
    /// A wrapper of one native handle. <see cref="Dispose"/> frees it; a second Dispose and any
    /// other call after that throw <see cref="ZooDisposedException"/> (a handle has one owner:
    /// a second Dispose means two parts of the program think they own it, which in C would be a
    /// double free, so it is reported rather than ignored; code that may legitimately see a
    /// disposed object checks <see cref="IsDisposed"/> first). The native handle is freed
    /// exactly once whatever happens. Undisposed handles are freed by the finalizer.
    /// </summary>
    public abstract class ZooObject : IDisposable
    {
        readonly ZooSafeHandle handle;

        internal ZooObject(ZooSafeHandle handle)
        {
            this.handle = handle;
        }

        /// <summary>Whether <see cref="Dispose"/> was called.</summary>
        public bool IsDisposed { get { return handle.IsClosed; } }

        /// <summary>Throws <see cref="ZooDisposedException"/> when disposed: for what a wrapper answers without a native call (<paramref name="member"/>, e.g. <c>Joints</c>).</summary>
        internal void ThrowIfDisposed(string member)
        {
            if (!handle.IsClosed) return;
            var name = GetType().Name;
            throw new ZooDisposedException(name, ZooStatus.NullPointer,
                name + "." + member + ": this " + name + " is disposed; read it before disposing it, or keep it alive while it is used");
        }

        /// <summary>Frees the native handle. Throws <see cref="ZooDisposedException"/> when it was already disposed (nothing is freed twice).</summary>
        public void Dispose()
        {
            if (handle.IsClosed)
            {
                var name = GetType().Name;
                throw new ZooDisposedException(name, ZooStatus.NullPointer,
                    name + ".Dispose: this " + name + " is already disposed (it was disposed twice: give it one owner that disposes it, or check IsDisposed before disposing)");
            }
            handle.Dispose();
        }

        /// <summary>The native pointer for one call (NULL once disposed or for a null wrapper); pair with <see cref="Exit"/> in a finally block.</summary>
        internal static IntPtr Enter(ZooObject o, ref bool entered)
        {
            if (o == null || o.handle.IsClosed) return IntPtr.Zero;
            o.handle.DangerousAddRef(ref entered);
            return o.handle.DangerousGetHandle();
        }

        internal static void Exit(ZooObject o, bool entered)
        {
            if (entered) o.handle.DangerousRelease();
        }

        /// <summary>Creates a handle of <paramref name="kind"/> from the pointer a <c>zoo_*_new</c> call wrote.</summary>
        internal static ZooSafeHandle Wrap(HandleKind kind, IntPtr pointer)
        {
            var h = new ZooSafeHandle(kind);
            h.Set(pointer);
            return h;
        }
    }

    /// <summary>Statuses to exceptions.</summary>
    internal static unsafe class Errors
    {
        /// <summary>A static NUL-terminated UTF-8 string of the library (<c>zoo_version_string</c>, <c>zoo_status_string</c>) or a message valid during a callback.</summary>
        internal static string Utf8(byte* text)
        {
            if (text == null) return "";
            int n = 0;
            while (text[n] != 0) n++;
            return Encoding.UTF8.GetString(text, n);
        }

        /// <summary>The calling thread's last error message (allocates: only on a refusal).</summary>
        internal static string LastError()
        {
            var n = (int)ZooNative.zoo_last_error(null, UIntPtr.Zero).ToUInt64();
            if (n == 0) return "(the runtime left no message)";
            var bytes = new byte[n + 1];
            fixed (byte* b = bytes) ZooNative.zoo_last_error(b, (UIntPtr)(ulong)bytes.Length);
            return Encoding.UTF8.GetString(bytes, 0, n);
        }

        /// <summary>Throws for a status other than OK (nothing allocated when it is OK).</summary>
        internal static void Check(ZooStatus status, ZooObject a = null, ZooObject b = null)
        {
            if (status != ZooStatus.Ok) throw Fail(status, a, b);
        }

        /// <summary>The exception of a refused call on handles <paramref name="a"/> and <paramref name="b"/>.</summary>
        internal static Exception Fail(ZooStatus status, ZooObject a = null, ZooObject b = null)
        {
            var message = LastError();
            var disposed = a != null && a.IsDisposed ? a : b != null && b.IsDisposed ? b : null;
            if (disposed != null && status == ZooStatus.NullPointer)
                return new ZooDisposedException(disposed.GetType().Name, status, disposed.GetType().Name + " is disposed: " + message);
            return new ZooException(status, message);
        }

        /// <summary>A refusal by the wrapper itself, where the C function cannot check (a buffer the C ABI takes without a length), worded as the runtime words its own.</summary>
        internal static ZooException Invalid(string function, string message)
        {
            return new ZooException(ZooStatus.InvalidArgument, function + ": " + message);
        }
    }

    /// <summary>Conversions between C# and C sizes.</summary>
    internal static class Size
    {
        /// <summary>
        /// A count or size argument as a size_t: a negative one is refused with an
        /// <see cref="ArgumentOutOfRangeException"/> naming the parameter (<paramref name="name"/>) and
        /// the C function or constructor (<paramref name="where"/>), before anything is allocated.
        /// </summary>
        internal static UIntPtr Count(int value, string name, string where)
        {
            if (value < 0)
                throw new ArgumentOutOfRangeException(name, value, where + ": `" + name + "` is " + value + ", a negative count or size, which C's size_t does not have");
            return (UIntPtr)(uint)value;
        }

        /// <summary>An int as a size_t (a negative value becomes a huge one, which the runtime refuses).</summary>
        internal static UIntPtr Of(int value)
        {
            return (UIntPtr)(ulong)(long)value;
        }

        internal static int Int(UIntPtr value)
        {
            return (int)value.ToUInt64();
        }

        /// <summary><paramref name="array"/>, grown to hold at least <paramref name="n"/> values (allocates only when it grows).</summary>
        internal static T[] Fit<T>(ref T[] array, int n)
        {
            if (array == null || array.Length < n) array = new T[Math.Max(n, 1)];
            return array;
        }
    }
}
