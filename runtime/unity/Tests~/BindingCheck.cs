// The binding check: the compiled bindings (the Zoo.Native namespace of Zoo.Runtime.dll) against
// zoo.h, both ways. Every function of the header has a P/Invoke of the same name, entry point,
// calling convention, return type, parameter names and types (bool marshalled as one byte); every
// enum the same members and values; every struct the same fields in the same order with the same
// C layout (offsets and size computed from the header for this platform, compared with the
// marshalled layout); every opaque type an empty struct; every function-pointer typedef a delegate
// of the same signature, called Cdecl; every integer #define a constant of ZooNative of the same
// value (ZOO_ABI_VERSION a uint). And nothing more: a binding of a function or a type the header no
// longer has fails too.
using System;
using System.Collections.Generic;
using System.Linq;
using System.Reflection;
using System.Runtime.InteropServices;

namespace Zoo.Tests
{
    static class BindingCheck
    {
        /// <summary>The problems (empty when the bindings match the header) and a summary line.</summary>
        public static List<string> Run(CHeader h, Assembly bindings, out string summary)
        {
            var problems = new List<string>();
            var native = bindings.GetType(Mapping.Namespace + ".ZooNative");
            if (native == null)
            {
                summary = "";
                problems.Add("no class Zoo.Native.ZooNative in " + bindings.GetName().Name);
                return problems;
            }
            CheckVersion(h, native, problems);
            CheckConstants(h, native, problems);
            var known = new HashSet<string> { "ZooNative", "ZooFloat3", "ZooFloat4" };
            // ZooLogLevel is the type of zoo_set_log_callback's `max_level` and of the callback's
            // `level` (both int32_t in zoo.h, whose comments name its values ZOO_LOG_LEVEL_*). A
            // header that declares the enum has it checked below like every enum; one that only
            // names it leaves the C# enum unchecked rather than "removed from the C ABI".
            if (!h.Enums.Any(e => e.Name == "ZooLogLevel")) known.Add("ZooLogLevel");
            foreach (var c in h.Callbacks) { known.Add(c.Name); CheckCallback(c, bindings, problems); }
            foreach (var e in h.Enums) { known.Add(e.Name); CheckEnum(e, bindings, problems); }
            foreach (var s in h.Structs) { known.Add(s.Name); CheckStruct(s, h, bindings, problems); }
            foreach (var o in h.Opaque) { known.Add(o); CheckOpaque(o, bindings, problems); }
            foreach (var t in bindings.GetTypes().Where(t => t.Namespace == Mapping.Namespace && t.IsPublic && !known.Contains(t.Name)))
                problems.Add("type " + t.FullName + " has no type in zoo.h (removed from the C ABI?): remove it from Runtime/Native");
            var methods = native.GetMethods(BindingFlags.Public | BindingFlags.NonPublic | BindingFlags.Static)
                .Where(m => (m.Attributes & MethodAttributes.PinvokeImpl) != 0).ToList();
            foreach (var f in h.Functions) CheckFunction(f, bindings, methods, problems);
            var names = new HashSet<string>(h.Functions.Select(f => f.Name));
            foreach (var m in methods)
            {
                var entry = EntryPoint(m);
                if (!names.Contains(entry))
                    problems.Add("ZooNative." + m.Name + " binds `" + entry + "`, which zoo.h does not declare (removed from the C ABI?): regenerate ZooNative.Functions.cs");
            }
            summary = string.Format("{0} functions, {1} structs, {2} enums, {3} opaque types, {4} callback types, {5} constants, C ABI version {6}",
                h.Functions.Count, h.Structs.Count, h.Enums.Count, h.Opaque.Count, h.Callbacks.Count, h.Constants.Count, h.AbiVersion);
            return problems;
        }

        static void CheckVersion(CHeader h, Type native, List<string> problems)
        {
            var field = native.GetField("ZOO_ABI_VERSION", BindingFlags.Public | BindingFlags.Static);
            if (field == null || field.FieldType != typeof(uint))
                problems.Add("ZooNative has no `public const uint ZOO_ABI_VERSION`");
            else if ((uint)field.GetRawConstantValue() != h.AbiVersion)
                problems.Add("ZooNative.ZOO_ABI_VERSION is " + field.GetRawConstantValue() + ", zoo.h's is " + h.AbiVersion + ": regenerate ZooNative.Functions.cs");
        }

        static void CheckConstants(CHeader h, Type native, List<string> problems)
        {
            var names = new HashSet<string>();
            foreach (var c in h.Constants.Where(c => c.Name != "ZOO_ABI_VERSION"))
            {
                names.Add(c.Name);
                var field = native.GetField(c.Name, BindingFlags.Public | BindingFlags.Static);
                if (field == null || !field.IsLiteral)
                    problems.Add("zoo.h's #define " + c.Name + " " + c.Value + " has no constant in ZooNative; add (or regenerate ZooNative.Functions.cs):\n        " + Mapping.ConstantDeclaration(c.Name, c.Value));
                else if (Convert.ToInt64(field.GetRawConstantValue()) != c.Value)
                    problems.Add("ZooNative." + c.Name + " is " + field.GetRawConstantValue() + ", zoo.h's is " + c.Value + ": regenerate ZooNative.Functions.cs");
            }
            foreach (var f in native.GetFields(BindingFlags.Public | BindingFlags.Static).Where(f => f.IsLiteral && f.Name.StartsWith("ZOO_", StringComparison.Ordinal)))
                if (f.Name != "ZOO_ABI_VERSION" && !names.Contains(f.Name))
                    problems.Add("ZooNative." + f.Name + " has no #define in zoo.h (removed from the C ABI?): regenerate ZooNative.Functions.cs");
        }

        static void CheckCallback(CCallback c, Assembly bindings, List<string> problems)
        {
            var t = bindings.GetType(Mapping.Namespace + "." + c.Name);
            if (t == null || !typeof(Delegate).IsAssignableFrom(t))
            {
                problems.Add("function-pointer typedef " + c.Name + " has no C# delegate " + Mapping.Namespace + "." + c.Name);
                return;
            }
            var diffs = new List<string>();
            var ufp = (UnmanagedFunctionPointerAttribute)t.GetCustomAttributes(typeof(UnmanagedFunctionPointerAttribute), false).FirstOrDefault();
            if (ufp == null || ufp.CallingConvention != CallingConvention.Cdecl) diffs.Add("needs [UnmanagedFunctionPointer(CallingConvention.Cdecl)]");
            var invoke = t.GetMethod("Invoke");
            string why;
            var ret = Mapping.Resolve(c.Return, bindings, out why);
            if (ret == null) diffs.Add("return: " + why);
            else if (invoke.ReturnType != ret) diffs.Add("returns " + invoke.ReturnType + ", zoo.h " + c.Return + " (" + ret + ")");
            var ps = invoke.GetParameters();
            if (ps.Length != c.Params.Count) diffs.Add("takes " + ps.Length + " parameters, zoo.h " + c.Params.Count);
            for (int i = 0; i < Math.Min(ps.Length, c.Params.Count); i++)
            {
                var cp = c.Params[i];
                var pt = Mapping.Resolve(cp.Type, bindings, out why);
                if (ps[i].Name != cp.Name) diffs.Add("parameter " + i + " is `" + ps[i].Name + "`, zoo.h's `" + cp.Name + "`");
                if (pt == null) diffs.Add("parameter `" + cp.Name + "`: " + why);
                else if (ps[i].ParameterType != pt) diffs.Add("parameter `" + cp.Name + "` is " + ps[i].ParameterType + ", zoo.h " + cp.Type + " (" + pt + ")");
                if (pt == typeof(bool) && !MarshalledAsByte(ps[i].GetCustomAttributes(false)))
                    diffs.Add("parameter `" + cp.Name + "` is a C bool (one byte): mark it [MarshalAs(UnmanagedType.U1)]");
            }
            if (diffs.Count > 0) problems.Add("delegate " + t.FullName + " differs from zoo.h's " + c.Name + ": " + string.Join("; ", diffs));
        }

        static string EntryPoint(MethodInfo m)
        {
            var a = (DllImportAttribute)m.GetCustomAttributes(typeof(DllImportAttribute), false).FirstOrDefault();
            return a == null ? m.Name : (a.EntryPoint ?? m.Name);
        }

        static bool MarshalledAsByte(object[] attributes)
        {
            return attributes.OfType<MarshalAsAttribute>().Any(a => a.Value == UnmanagedType.U1 || a.Value == UnmanagedType.I1);
        }

        static void CheckFunction(CFunction f, Assembly bindings, List<MethodInfo> methods, List<string> problems)
        {
            string expected;
            try { expected = Mapping.Declaration(f); }
            catch (FormatException e) { expected = "(none: " + e.Message + ")"; }
            var matches = methods.Where(m => EntryPoint(m) == f.Name).ToList();
            if (matches.Count == 0)
            {
                problems.Add(f.Name + " has no binding in ZooNative; add (or regenerate ZooNative.Functions.cs):\n        " + expected);
                return;
            }
            if (matches.Count > 1) { problems.Add(f.Name + " has " + matches.Count + " bindings in ZooNative; keep one"); return; }
            var m0 = matches[0];
            var where = "ZooNative." + m0.Name + " (" + f.Name + ")";
            var diffs = new List<string>();
            var dll = (DllImportAttribute)m0.GetCustomAttributes(typeof(DllImportAttribute), false).FirstOrDefault();
            if (m0.Name != f.Name) diffs.Add("is named " + m0.Name);
            if (dll == null) diffs.Add("has no DllImport attribute");
            else
            {
                if (dll.Value != "zoo_capi") diffs.Add("imports from `" + dll.Value + "`, not zoo_capi");
                if (dll.CallingConvention != CallingConvention.Cdecl) diffs.Add("uses the calling convention " + dll.CallingConvention + ", not Cdecl");
            }
            string why;
            var ret = Mapping.Resolve(f.Return, bindings, out why);
            if (ret == null) diffs.Add("return: " + why);
            else if (m0.ReturnType != ret) diffs.Add("returns " + m0.ReturnType + ", zoo.h " + f.Return + " (" + ret + ")");
            var ps = m0.GetParameters();
            if (ps.Length != f.Params.Count) diffs.Add("takes " + ps.Length + " parameters, zoo.h " + f.Params.Count);
            for (int i = 0; i < Math.Min(ps.Length, f.Params.Count); i++)
            {
                var cp = f.Params[i];
                var t = Mapping.Resolve(cp.Type, bindings, out why);
                if (ps[i].Name != cp.Name) diffs.Add("parameter " + i + " is `" + ps[i].Name + "`, zoo.h's `" + cp.Name + "`");
                if (t == null) diffs.Add("parameter `" + cp.Name + "`: " + why);
                else if (ps[i].ParameterType != t) diffs.Add("parameter `" + cp.Name + "` is " + ps[i].ParameterType + ", zoo.h " + cp.Type + " (" + t + ")");
                if (t == typeof(bool) && !MarshalledAsByte(ps[i].GetCustomAttributes(false)))
                    diffs.Add("parameter `" + cp.Name + "` is a C bool (one byte): mark it [MarshalAs(UnmanagedType.U1)]");
            }
            if (diffs.Count > 0)
                problems.Add(where + " differs from zoo.h: " + string.Join("; ", diffs) + "; zoo.h's is:\n        " + expected);
        }

        static void CheckEnum(CEnum e, Assembly bindings, List<string> problems)
        {
            var t = bindings.GetType(Mapping.Namespace + "." + e.Name);
            if (t == null || !t.IsEnum) { problems.Add("enum " + e.Name + " has no C# enum " + Mapping.Namespace + "." + e.Name); return; }
            if (Enum.GetUnderlyingType(t) != typeof(int)) problems.Add("enum " + t.FullName + " is " + Enum.GetUnderlyingType(t) + ", not int (a C enum)");
            var prefix = Mapping.EnumPrefix(e.Name);
            var names = new HashSet<string>();
            foreach (var kv in e.Members)
            {
                if (!kv.Key.StartsWith(prefix, StringComparison.Ordinal)) { problems.Add("enum member " + kv.Key + " lacks the prefix " + prefix); continue; }
                var name = Mapping.Pascal(kv.Key.Substring(prefix.Length));
                names.Add(name);
                var f = t.GetField(name, BindingFlags.Public | BindingFlags.Static);
                if (f == null) problems.Add(kv.Key + " has no member " + t.Name + "." + name);
                else if (Convert.ToInt64(f.GetRawConstantValue()) != kv.Value) problems.Add(t.Name + "." + name + " is " + f.GetRawConstantValue() + ", zoo.h's " + kv.Key + " is " + kv.Value);
            }
            foreach (var f in t.GetFields(BindingFlags.Public | BindingFlags.Static).Where(f => !names.Contains(f.Name)))
                problems.Add(t.Name + "." + f.Name + " has no member in zoo.h's " + e.Name);
        }

        static void CheckOpaque(string name, Assembly bindings, List<string> problems)
        {
            var t = bindings.GetType(Mapping.Namespace + "." + name);
            if (t == null || !t.IsValueType) { problems.Add("opaque " + name + " has no struct " + Mapping.Namespace + "." + name); return; }
            if (t.GetFields(BindingFlags.Instance | BindingFlags.Public | BindingFlags.NonPublic).Length != 0)
                problems.Add(t.FullName + " is opaque in zoo.h (only ever behind a pointer): it must have no fields");
        }

        /// <summary>Size and alignment of a C type on this platform (C struct layout rules).</summary>
        static void CLayout(CType t, int arrayLength, CHeader h, out int size, out int align)
        {
            if (t.Pointers > 0 || t.IsCallback) { size = align = IntPtr.Size; }
            else if (t.IsEnum) { size = align = 4; }
            else if (t.IsStruct)
            {
                var s = h.Structs.FirstOrDefault(x => x.Name == t.Base);
                if (s == null) throw new InvalidOperationException("struct " + t.Base + " is used by value but not defined in zoo.h");
                int[] offsets;
                StructLayoutOf(s, h, out offsets, out size, out align);
            }
            else
            {
                switch (t.Base)
                {
                    case "bool": case "uint8_t": case "char": size = align = 1; break;
                    case "float": case "int32_t": case "uint32_t": size = align = 4; break;
                    case "uint64_t": size = align = 8; break;
                    case "size_t": size = align = IntPtr.Size; break;
                    default: throw new InvalidOperationException("no C layout for `" + t.Base + "`");
                }
            }
            if (arrayLength > 0) size *= arrayLength;
        }

        static void StructLayoutOf(CStruct s, CHeader h, out int[] offsets, out int size, out int align)
        {
            offsets = new int[s.Fields.Count];
            int at = 0;
            align = 1;
            for (int i = 0; i < s.Fields.Count; i++)
            {
                int fs, fa;
                CLayout(s.Fields[i].Type, s.Fields[i].ArrayLength, h, out fs, out fa);
                at = (at + fa - 1) / fa * fa;
                offsets[i] = at;
                at += fs;
                align = Math.Max(align, fa);
            }
            size = (at + align - 1) / align * align;
        }

        static void CheckStruct(CStruct s, CHeader h, Assembly bindings, List<string> problems)
        {
            var t = bindings.GetType(Mapping.Namespace + "." + s.Name);
            if (t == null || !t.IsValueType || t.IsEnum) { problems.Add("struct " + s.Name + " has no C# struct " + Mapping.Namespace + "." + s.Name); return; }
            if (!t.IsLayoutSequential) problems.Add(t.FullName + " needs [StructLayout(LayoutKind.Sequential)]");
            var fields = t.GetFields(BindingFlags.Instance | BindingFlags.Public | BindingFlags.NonPublic).OrderBy(f => f.MetadataToken).ToArray();
            if (fields.Length != s.Fields.Count)
                problems.Add(t.Name + " has " + fields.Length + " fields, zoo.h's " + s.Name + " " + s.Fields.Count + " (" + string.Join(", ", s.Fields.Select(f => f.Name)) + ")");
            int[] offsets;
            int size, align;
            StructLayoutOf(s, h, out offsets, out size, out align);
            for (int i = 0; i < Math.Min(fields.Length, s.Fields.Count); i++)
            {
                var cf = s.Fields[i];
                var f = fields[i];
                var name = Mapping.Pascal(cf.Name);
                if (f.Name != name) problems.Add(t.Name + " field " + i + " is " + f.Name + ", zoo.h's `" + cf.Name + "` (" + name + ")");
                string why;
                if (cf.ArrayLength > 0)
                {
                    var elem = Mapping.Resolve(cf.Type, bindings, out why);
                    var inner = f.FieldType.GetFields(BindingFlags.Instance | BindingFlags.Public | BindingFlags.NonPublic);
                    if (!f.FieldType.IsValueType || inner.Length != cf.ArrayLength || inner.Any(x => x.FieldType != elem))
                        problems.Add(t.Name + "." + f.Name + " is " + f.FieldType.Name + ", zoo.h's `" + cf.Type + " " + cf.Name + "[" + cf.ArrayLength + "]` needs a struct of " + cf.ArrayLength + " " + elem + " fields (ZooFloat" + cf.ArrayLength + ")");
                }
                else
                {
                    var ft = Mapping.Resolve(cf.Type, bindings, out why);
                    if (ft == null) problems.Add(t.Name + "." + f.Name + ": " + why);
                    else if (f.FieldType != ft) problems.Add(t.Name + "." + f.Name + " is " + f.FieldType + ", zoo.h's `" + cf.Name + "` is " + cf.Type + " (" + ft + ")");
                    if (ft == typeof(bool) && !MarshalledAsByte(f.GetCustomAttributes(false)))
                        problems.Add(t.Name + "." + f.Name + " is a C bool (one byte): mark it [MarshalAs(UnmanagedType.U1)]");
                }
                if (f.Name == name)
                {
                    int offset;
                    try { offset = (int)Marshal.OffsetOf(t, f.Name); }
                    catch (ArgumentException) { continue; }
                    if (offset != offsets[i]) problems.Add(t.Name + "." + f.Name + " is at byte " + offset + ", zoo.h's `" + cf.Name + "` at " + offsets[i]);
                }
            }
            int csize = -1;
            try { csize = Marshal.SizeOf(t); }
            catch (ArgumentException) { }
            if (csize != size) problems.Add(t.Name + " is " + csize + " bytes, zoo.h's " + s.Name + " " + size);
        }
    }
}
