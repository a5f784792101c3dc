// The native library the bindings call (the hand-written part of ZooNative; the functions are in
// ZooNative.Functions.cs, generated from zoo.h).
namespace Zoo.Native
{
    /// <summary>
    /// The C ABI of the zoo runtime, function for function (<c>runtime/capi/include/zoo.h</c>): raw
    /// pointers, C names, status codes. Use the safe wrappers of the <c>Zoo</c> namespace unless you
    /// need a call they do not make.
    /// </summary>
    public static unsafe partial class ZooNative
    {
        /// <summary>
        /// The native library: <c>libzoo_capi.so</c> (Linux), <c>libzoo_capi.dylib</c> (macOS),
        /// <c>zoo_capi.dll</c> (Windows), under the package's <c>Runtime/Plugins/&lt;platform&gt;/</c>.
        /// Platforms that link native code statically (iOS, WebGL) need <c>"__Internal"</c> here
        /// and the static library <c>libzoo_capi.a</c> in the player build.
        /// </summary>
        public const string Library = "zoo_capi";
    }
}
