// A reader of runtime/capi/include/zoo.h as cbindgen writes it (C99 declarations: typedef enums,
// typedef structs, opaque typedefs, function-pointer typedefs, integer #defines such as
// ZOO_ABI_VERSION and ZOO_MAX_BATCH, functions), and the C-to-C# mapping
// of the bindings in Runtime/Native: what BindingCheck.cs compares the compiled bindings with and
// what Tools~/update-bindings.sh writes ZooNative.Functions.cs from. Anything else in the
// header is an error, so that a new kind of declaration cannot slip past the check.
using System;
using System.Collections.Generic;
using System.Globalization;
using System.Linq;
using System.Text;
using System.Text.RegularExpressions;

namespace Zoo.Tests
{
    /// <summary>A C type: a base name (<c>float</c>, <c>size_t</c>, <c>ZooModel</c>, <c>ZooLogCallback</c>), whether it is an enum, a struct or a function-pointer typedef of the header, its pointer depth.</summary>
    sealed class CType
    {
        public string Base;
        public bool IsEnum;
        public bool IsStruct;
        /// <summary>A function-pointer typedef of the header (<c>typedef void (*ZooLogCallback)(...)</c>), bound by a C# delegate of the same name.</summary>
        public bool IsCallback;
        public int Pointers;

        public static CType Parse(string text)
        {
            var t = new CType();
            t.Pointers = text.Count(c => c == '*');
            var words = text.Replace("*", " ").Split(new[] { ' ' }, StringSplitOptions.RemoveEmptyEntries).ToList();
            words.Remove("const");
            if (words.Count > 0 && words[0] == "enum") { t.IsEnum = true; words.RemoveAt(0); }
            else if (words.Count > 0 && words[0] == "struct") { t.IsStruct = true; words.RemoveAt(0); }
            if (words.Count != 1) throw new FormatException("cannot read the C type `" + text + "`");
            t.Base = words[0];
            return t;
        }

        public override string ToString()
        {
            return (IsEnum ? "enum " : IsStruct ? "struct " : "") + Base + new string('*', Pointers);
        }
    }

    sealed class CField
    {
        public CType Type;
        public string Name;
        /// <summary>N of <c>type name[N]</c>; 0 for a scalar.</summary>
        public int ArrayLength;
    }

    sealed class CStruct
    {
        public string Name;
        public List<CField> Fields = new List<CField>();
    }

    sealed class CEnum
    {
        public string Name;
        public List<KeyValuePair<string, long>> Members = new List<KeyValuePair<string, long>>();
    }

    sealed class CParam
    {
        public CType Type;
        public string Name;
    }

    sealed class CFunction
    {
        public string Name;
        public CType Return;
        public List<CParam> Params = new List<CParam>();
        public List<string> Doc = new List<string>();
    }

    /// <summary>An integer <c>#define</c> of the header and its comment.</summary>
    sealed class CConstant
    {
        public string Name;
        public long Value;
        public List<string> Doc = new List<string>();
    }

    /// <summary>A function-pointer typedef: <c>typedef RETURN (*NAME)(PARAMS);</c>.</summary>
    sealed class CCallback
    {
        public string Name;
        public CType Return;
        public List<CParam> Params = new List<CParam>();
    }

    sealed class CHeader
    {
        public uint AbiVersion;
        /// <summary>Every <c>#define ZOO_NAME value</c> with an integer value, in the header's order (ZOO_ABI_VERSION, ZOO_MAX_BATCH, ...).</summary>
        public List<CConstant> Constants = new List<CConstant>();
        public List<CCallback> Callbacks = new List<CCallback>();
        public List<CEnum> Enums = new List<CEnum>();
        public List<CStruct> Structs = new List<CStruct>();
        public List<string> Opaque = new List<string>();
        public List<CFunction> Functions = new List<CFunction>();

        static readonly Regex EnumRx = new Regex(@"^typedef enum (\w+) \{(.*)\} (\w+);$");
        static readonly Regex StructRx = new Regex(@"^typedef struct (\w+) \{(.*)\} (\w+);$");
        static readonly Regex OpaqueRx = new Regex(@"^typedef struct (\w+) (\w+);$");
        static readonly Regex FunctionRx = new Regex(@"^(.*?)\b(zoo_\w+)\((.*)\);$");
        static readonly Regex CallbackRx = new Regex(@"^typedef (.*?)\(\*(\w+)\)\((.*)\);$");
        static readonly Regex FieldRx = new Regex(@"^(.*?)(\w+)(\[(\d+)\])?$");
        static readonly Regex DefineRx = new Regex(@"^#define (ZOO_\w+) (\d+)$");

        public static CHeader Parse(string text)
        {
            var h = new CHeader();
            bool sawVersion = false;
            text = Regex.Replace(text, @"/\*.*?\*/", " ", RegexOptions.Singleline);
            var doc = new List<string>();
            var statement = new StringBuilder();
            var statementDoc = new List<string>();
            int depth = 0;
            foreach (var raw in text.Split('\n'))
            {
                var line = raw.Trim();
                if (line.StartsWith("//", StringComparison.Ordinal))
                {
                    if (statement.Length == 0) doc.Add(line.Length > 2 && line[2] == ' ' ? line.Substring(3) : line.Substring(2));
                    continue;
                }
                if (line.StartsWith("#", StringComparison.Ordinal))
                {
                    var m = DefineRx.Match(line);
                    if (m.Success)
                    {
                        var value = long.Parse(m.Groups[2].Value, CultureInfo.InvariantCulture);
                        h.Constants.Add(new CConstant { Name = m.Groups[1].Value, Value = value, Doc = new List<string>(doc) });
                        if (m.Groups[1].Value == "ZOO_ABI_VERSION") { h.AbiVersion = (uint)value; sawVersion = true; }
                    }
                    doc.Clear();
                    continue;
                }
                int comment = line.IndexOf("//", StringComparison.Ordinal);
                if (comment >= 0) line = line.Substring(0, comment).Trim();
                if (line.Length == 0) { if (statement.Length == 0) doc.Clear(); continue; }
                if (line == "extern \"C\" {" || line == "}") { doc.Clear(); continue; }
                if (statement.Length == 0) { statementDoc = new List<string>(doc); doc.Clear(); }
                statement.Append(line).Append(' ');
                depth += line.Count(c => c == '{') - line.Count(c => c == '}');
                if (depth == 0 && line.EndsWith(";", StringComparison.Ordinal))
                {
                    h.Add(Regex.Replace(statement.ToString(), @"\s+", " ").Replace("( ", "(").Replace(" )", ")").Replace("{ ", "{").Replace(" }", "}").Trim(), statementDoc);
                    statement.Clear();
                }
            }
            if (statement.Length != 0) throw new FormatException("zoo.h ends inside a declaration: " + statement);
            if (!sawVersion) throw new FormatException("zoo.h has no `#define ZOO_ABI_VERSION`");
            h.MarkCallbacks();
            return h;
        }

        /// <summary>Marks every use of a function-pointer typedef (parameters, fields, returns) as a callback type.</summary>
        void MarkCallbacks()
        {
            var names = new HashSet<string>(Callbacks.Select(c => c.Name));
            var types = new List<CType>();
            foreach (var f in Functions) { types.Add(f.Return); types.AddRange(f.Params.Select(p => p.Type)); }
            foreach (var c in Callbacks) { types.Add(c.Return); types.AddRange(c.Params.Select(p => p.Type)); }
            foreach (var s in Structs) types.AddRange(s.Fields.Select(f => f.Type));
            foreach (var t in types)
                if (!t.IsEnum && !t.IsStruct && names.Contains(t.Base)) t.IsCallback = true;
        }

        static List<CParam> Params(string text)
        {
            var list = new List<CParam>();
            var ps = text.Trim();
            if (ps == "void" || ps.Length == 0) return list;
            foreach (var p in ps.Split(','))
            {
                var pm = Regex.Match(p.Trim(), @"^(.*?)(\w+)$");
                list.Add(new CParam { Type = CType.Parse(pm.Groups[1].Value), Name = pm.Groups[2].Value });
            }
            return list;
        }

        void Add(string s, List<string> doc)
        {
            Match m;
            if ((m = EnumRx.Match(s)).Success)
            {
                var e = new CEnum { Name = m.Groups[1].Value };
                foreach (var member in m.Groups[2].Value.Split(new[] { ',' }, StringSplitOptions.RemoveEmptyEntries))
                {
                    var parts = member.Split('=');
                    if (parts.Length != 2) throw new FormatException("cannot read the enum member `" + member + "` of " + e.Name + " (every member needs an explicit value)");
                    e.Members.Add(new KeyValuePair<string, long>(parts[0].Trim(), long.Parse(parts[1].Trim(), CultureInfo.InvariantCulture)));
                }
                Enums.Add(e);
            }
            else if ((m = StructRx.Match(s)).Success)
            {
                var st = new CStruct { Name = m.Groups[1].Value };
                foreach (var field in m.Groups[2].Value.Split(new[] { ';' }, StringSplitOptions.RemoveEmptyEntries))
                {
                    var f = field.Trim();
                    if (f.Length == 0) continue;
                    var fm = FieldRx.Match(f);
                    if (!fm.Success) throw new FormatException("cannot read the field `" + f + "` of " + st.Name);
                    st.Fields.Add(new CField
                    {
                        Type = CType.Parse(fm.Groups[1].Value),
                        Name = fm.Groups[2].Value,
                        ArrayLength = fm.Groups[4].Success ? int.Parse(fm.Groups[4].Value, CultureInfo.InvariantCulture) : 0,
                    });
                }
                Structs.Add(st);
            }
            else if ((m = OpaqueRx.Match(s)).Success)
            {
                Opaque.Add(m.Groups[1].Value);
            }
            else if ((m = CallbackRx.Match(s)).Success)
            {
                Callbacks.Add(new CCallback { Name = m.Groups[2].Value, Return = CType.Parse(m.Groups[1].Value), Params = Params(m.Groups[3].Value) });
            }
            else if ((m = FunctionRx.Match(s)).Success)
            {
                Functions.Add(new CFunction { Name = m.Groups[2].Value, Return = CType.Parse(m.Groups[1].Value), Doc = doc, Params = Params(m.Groups[3].Value) });
            }
            else
            {
                throw new FormatException("zoo.h has a declaration the binding check does not know: `" + s + "`; teach Tests~/Header.cs to read it");
            }
        }
    }

    /// <summary>The C-to-C# mapping of the bindings.</summary>
    static class Mapping
    {
        public const string Namespace = "Zoo.Native";

        static readonly Dictionary<string, Type> Primitives = new Dictionary<string, Type>
        {
            { "void", typeof(void) },
            { "float", typeof(float) },
            { "bool", typeof(bool) },
            { "char", typeof(byte) },
            { "uint8_t", typeof(byte) },
            { "int32_t", typeof(int) },
            { "uint32_t", typeof(uint) },
            { "uint64_t", typeof(ulong) },
            { "size_t", typeof(UIntPtr) },
        };

        static readonly Dictionary<Type, string> Keywords = new Dictionary<Type, string>
        {
            { typeof(void), "void" }, { typeof(float), "float" }, { typeof(bool), "bool" }, { typeof(byte), "byte" },
            { typeof(int), "int" }, { typeof(uint), "uint" }, { typeof(ulong), "ulong" }, { typeof(UIntPtr), "UIntPtr" },
        };

        static readonly HashSet<string> CSharpKeywords = new HashSet<string> { "out", "fixed", "ref", "in", "params", "object", "string", "base", "this" };

        /// <summary>The C# type of a C type, or null when the bindings have none (<paramref name="why"/> says why).</summary>
        public static Type Resolve(CType t, System.Reflection.Assembly bindings, out string why)
        {
            why = null;
            Type b;
            if (t.IsCallback)
            {
                b = bindings.GetType(Namespace + "." + t.Base);
                if (b == null || !typeof(Delegate).IsAssignableFrom(b)) { why = "no delegate " + Namespace + "." + t.Base + " for zoo.h's function-pointer typedef " + t.Base; return null; }
            }
            else if (t.IsEnum || t.IsStruct)
            {
                b = bindings.GetType(Namespace + "." + t.Base);
                if (b == null) { why = "no type " + Namespace + "." + t.Base; return null; }
            }
            else if (!Primitives.TryGetValue(t.Base, out b))
            {
                why = "the C type `" + t.Base + "` has no C# mapping in Tests~/Header.cs";
                return null;
            }
            for (int i = 0; i < t.Pointers; i++) b = b.MakePointerType();
            return b;
        }

        /// <summary>C# source of a C type.</summary>
        public static string Source(CType t)
        {
            string b;
            Type p;
            if (t.IsEnum || t.IsStruct || t.IsCallback) b = t.Base;
            else if (Primitives.TryGetValue(t.Base, out p)) b = Keywords[p];
            else throw new FormatException("the C type `" + t.Base + "` has no C# mapping in Tests~/Header.cs");
            return b + new string('*', t.Pointers);
        }

        /// <summary>A C name in PascalCase (<c>root_position</c> to <c>RootPosition</c>).</summary>
        public static string Pascal(string snake)
        {
            var sb = new StringBuilder();
            foreach (var part in snake.ToLowerInvariant().Split(new[] { '_' }, StringSplitOptions.RemoveEmptyEntries))
                sb.Append(char.ToUpperInvariant(part[0])).Append(part.Substring(1));
            return sb.ToString();
        }

        /// <summary>The prefix of an enum's members: <c>ZooUpAxis</c> to <c>ZOO_UP_AXIS_</c>.</summary>
        public static string EnumPrefix(string name)
        {
            return Regex.Replace(name, "(?<=[a-z0-9])([A-Z])", "_$1").ToUpperInvariant() + "_";
        }

        /// <summary>A C identifier as a C# identifier.</summary>
        public static string Identifier(string name)
        {
            return CSharpKeywords.Contains(name) ? "@" + name : name;
        }

        /// <summary>The C# declaration of a function's binding.</summary>
        public static string Declaration(CFunction f)
        {
            var ps = f.Params.Select(p => (p.Type.Pointers == 0 && p.Type.Base == "bool" ? "[MarshalAs(UnmanagedType.U1)] " : "") + Source(p.Type) + " " + Identifier(p.Name));
            var ret = f.Return.Pointers == 0 && f.Return.Base == "bool" ? "[return: MarshalAs(UnmanagedType.U1)]\n        " : "";
            return "[DllImport(Library, EntryPoint = \"" + f.Name + "\", CallingConvention = CallingConvention.Cdecl, ExactSpelling = true)]\n        "
                + ret + "public static extern " + Source(f.Return) + " " + f.Name + "(" + string.Join(", ", ps) + ");";
        }

        /// <summary>A header comment as an XML doc comment: the first paragraph the summary, the rest remarks.</summary>
        public static string DocComment(List<string> doc, string indent)
        {
            var paragraphs = new List<List<string>> { new List<string>() };
            foreach (var l in doc)
            {
                if (l.Trim().Length == 0) paragraphs.Add(new List<string>());
                else paragraphs[paragraphs.Count - 1].Add(Xml(l.Trim().StartsWith("# ", StringComparison.Ordinal) ? l.Trim().Substring(2) + ":" : l.Trim()));
            }
            var sb = new StringBuilder();
            sb.Append(indent).Append("/// <summary>\n");
            foreach (var l in paragraphs[0]) sb.Append(indent).Append("/// ").Append(l).Append('\n');
            sb.Append(indent).Append("/// </summary>\n");
            var rest = paragraphs.Skip(1).Where(p => p.Count > 0).ToList();
            if (rest.Count > 0)
            {
                sb.Append(indent).Append("/// <remarks>\n");
                foreach (var p in rest)
                    foreach (var l in p) sb.Append(indent).Append("/// ").Append(l).Append('\n');
                sb.Append(indent).Append("/// </remarks>\n");
            }
            return sb.ToString();
        }

        static string Xml(string line)
        {
            line = line.Replace("&", "&amp;").Replace("<", "&lt;").Replace(">", "&gt;");
            line = Regex.Replace(line, @"\[`([^`]*)`\]", "<c>$1</c>");
            return Regex.Replace(line, @"`([^`]*)`", "<c>$1</c>");
        }

        /// <summary>The C# declaration of a <c>#define</c> of the header other than ZOO_ABI_VERSION: an int (a count, a length) when it fits, else a long.</summary>
        public static string ConstantDeclaration(string name, long value)
        {
            return (value <= int.MaxValue ? "public const int " : "public const long ") + name + " = " + value.ToString(CultureInfo.InvariantCulture) + ";";
        }

        /// <summary>The whole ZooNative.Functions.cs for a header.</summary>
        public static string Generate(CHeader h)
        {
            var sb = new StringBuilder();
            sb.Append("// Generated from runtime/capi/include/zoo.h by runtime/unity/Tools~/update-bindings.sh: do not edit;\n");
            sb.Append("// regenerate when the C ABI changes (Documentation~/zoo.md, \"Updating the bindings\").\n");
            sb.Append("using System;\nusing System.Runtime.InteropServices;\n\nnamespace Zoo.Native\n{\n");
            sb.Append("    /// <summary>The functions of the C ABI (zoo.h, C ABI version ").Append(h.AbiVersion).Append("), one P/Invoke each, with the C names and types.</summary>\n");
            sb.Append("    public static unsafe partial class ZooNative\n    {\n");
            sb.Append("        /// <summary>The C ABI version these bindings were generated from (<c>ZOO_ABI_VERSION</c> of zoo.h).</summary>\n");
            sb.Append("        public const uint ZOO_ABI_VERSION = ").Append(h.AbiVersion).Append(";\n");
            foreach (var c in h.Constants.Where(c => c.Name != "ZOO_ABI_VERSION"))
                sb.Append('\n').Append(DocComment(c.Doc, "        ")).Append("        ").Append(ConstantDeclaration(c.Name, c.Value)).Append('\n');
            foreach (var f in h.Functions)
            {
                sb.Append('\n').Append(DocComment(f.Doc, "        ")).Append("        ").Append(Declaration(f)).Append('\n');
            }
            sb.Append("    }\n}\n");
            return sb.ToString();
        }
    }
}
