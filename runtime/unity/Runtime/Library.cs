// The native library itself: its version (zoo_version_string, zoo_abi_version), the names of its
// statuses (zoo_status_string) and its log messages (zoo_set_log_callback) routed to a C# callback.
using System;
using Zoo.Native;

namespace Zoo
{
    /// <summary>
    /// The native library <c>zoo_capi</c>: <see cref="Version"/> for a log line, <see cref="Check"/> that it
    /// is there with the C ABI version of these bindings, <see cref="StatusName"/>, and
    /// <see cref="SetLogCallback"/> to receive its warnings (it never prints).
    /// </summary>
    public static unsafe class Library
    {
        /// <summary>
        /// The library's version, <c>zoo X.Y.Z (C ABI N)</c> (<c>zoo_version_string</c>): the release of zoo it was
        /// built from and its C ABI version. A library older than C ABI 3 has no version string: then
        /// <c>zoo (C ABI N)</c> with its <c>zoo_abi_version</c>.
        /// </summary>
        public static string Version
        {
            get
            {
                var abi = AbiVersion;
                try { return Errors.Utf8(ZooNative.zoo_version_string()); }
                catch (EntryPointNotFoundException) { return "zoo (C ABI " + abi + ")"; }
            }
        }

        /// <summary>The library's C ABI version (<c>zoo_abi_version</c>); these bindings need <see cref="ZooNative.ZOO_ABI_VERSION"/>.</summary>
        public static uint AbiVersion
        {
            get
            {
                try { return ZooNative.zoo_abi_version(); }
                catch (DllNotFoundException e) { throw Missing(e); }
            }
        }

        static DllNotFoundException Missing(DllNotFoundException e)
        {
            return new DllNotFoundException(
                "zoo: the native library zoo_capi (libzoo_capi.so, libzoo_capi.dylib or zoo_capi.dll) was not found: build it with "
                + "Tools~/build-native.sh and put it under the package's Runtime/Plugins/<platform>/ (Documentation~/zoo.md, Install)", e);
        }

        /// <summary>Throws when the native library is missing (<see cref="DllNotFoundException"/>) or of another C ABI version than these bindings (<see cref="ZooException"/>), saying what to do.</summary>
        public static void Check()
        {
            var version = AbiVersion;
            if (version != ZooNative.ZOO_ABI_VERSION)
                throw new ZooException(ZooStatus.LoadFailed, "zoo: the native library zoo_capi has C ABI version " + version + ", these bindings version "
                    + ZooNative.ZOO_ABI_VERSION + ": build the library from the same zoo checkout as the package (Tools~/build-native.sh)");
        }

        /// <summary>The C name of a status, e.g. <c>ZOO_STATUS_INVALID_ARGUMENT</c> (<c>zoo_status_string</c>; <c>ZOO_STATUS_UNKNOWN</c> for a value that is not a status).</summary>
        public static string StatusName(ZooStatus status)
        {
            try { return Errors.Utf8(ZooNative.zoo_status_string((int)status)); }
            catch (DllNotFoundException) { }
            catch (EntryPointNotFoundException) { }
            return Enum.IsDefined(typeof(ZooStatus), status) ? "ZOO_STATUS_" + status : "ZOO_STATUS_UNKNOWN";
        }

        // The handler of the library's log messages; the delegate the library calls is static and
        // lives as long as the process, so the library never calls a collected delegate.
        static volatile Action<ZooLogLevel, string> logHandler;
        static readonly ZooLogCallback logThunk = OnLog;
        static readonly object logLock = new object();

        /// <summary>
        /// Sends the library's log messages up to <paramref name="maxLevel"/> (<see cref="ZooLogLevel.Warning"/>:
        /// errors and warnings) to <paramref name="callback"/>; null stops logging (the default: the library logs
        /// nothing and never prints). Messages come from the library and the graph runtime it embeds (tract),
        /// on any thread that calls the library: the callback must be thread-safe and must not call the
        /// library; an exception it throws is dropped (it cannot unwind into native code). In Unity, e.g.
        /// <c>Library.SetLogCallback((level, message) =&gt; Debug.LogWarning("zoo: " + message))</c> once at start-up.
        /// The delegate is kept alive here until it is replaced (<c>zoo_set_log_callback</c>; a
        /// <paramref name="maxLevel"/> outside <see cref="ZooLogLevel"/> is refused, and so is a process that
        /// already has another Rust logger, with <see cref="ZooStatus.NotAvailable"/>).
        /// </summary>
        public static void SetLogCallback(Action<ZooLogLevel, string> callback, ZooLogLevel maxLevel = ZooLogLevel.Warning)
        {
            Check();
            lock (logLock)
            {
                var previous = logHandler;
                logHandler = callback;
                var s = ZooNative.zoo_set_log_callback(callback == null ? null : logThunk, null, (int)maxLevel);
                if (s != ZooStatus.Ok)
                {
                    logHandler = previous;
                    throw Errors.Fail(s);
                }
            }
        }

        [AOT.MonoPInvokeCallback(typeof(ZooLogCallback))]
        static void OnLog(int level, byte* message, void* userData)
        {
            var handler = logHandler;
            if (handler == null) return;
            try { handler((ZooLogLevel)level, Errors.Utf8(message)); }
            catch (Exception) { }
        }
    }
}

namespace AOT
{
    /// <summary>
    /// Marks a static method the native library calls back (IL2CPP, ahead-of-time platforms, needs it on
    /// every method passed to native code as a delegate; IL2CPP recognises the attribute by its name).
    /// </summary>
    [AttributeUsage(AttributeTargets.Method)]
    internal sealed class MonoPInvokeCallbackAttribute : Attribute
    {
        internal MonoPInvokeCallbackAttribute(Type type) { Type = type; }

        internal Type Type { get; private set; }
    }
}
