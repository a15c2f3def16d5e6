#!/usr/bin/env python3
"""Checks that tarmac's DDS IDL for a package says what its ROS 2 .msg files say.

The .msg files (idl/tarmac_msgs/msg/) are the reference. Each one is translated with ROS 2's own
translator, `rosidl translate --to idl` (Debian 12: rosidl-tools, python3-catkin-pkg,
python3-empy), into a temporary directory; the result is compared with the hand-kept IDL
(idl/tarmac_msgs.idl) struct by struct: field names, types and order, and the constants with
their types and values. It also checks that the .msg names follow ROS 2's rules (snake_case
fields that are no IDL, C++ or Python keyword; UPPER_CASE constants) and that the package builds
what it holds (CMakeLists.txt lists every .msg; the packages used are DEPENDENCIES and package.xml
<depend>s). Every difference is listed and the exit status is 1.

Translating a .msg needs none of its dependencies: rosidl only writes `#include
"std_msgs/msg/Header.idl"` for a field of another package, so Debian's rosidl-tools works without
any ROS 2 interface package installed (Debian 12 ships none).

Naming: rosidl writes `pkg::msg::Foo` and `pkg::msg::Foo_Constants`; the DDS wire names that
tarmac's IDL spells out are `pkg::msg::dds_::Foo_`, with constants staying in
`pkg::msg::Foo_Constants`. Fixed arrays, which rosidl writes as typedefs, are compared as
`T[N]`; annotations (@verbatim comments, @default) do not reach the wire and are not compared.

Usage:
  msg_idl_agreement.py --msg-dir idl/tarmac_msgs/msg --idl idl/tarmac_msgs.idl
  msg_idl_agreement.py --msg-dir ... --idl ... --self-test   # proves the check can fail

Standard library only.
"""

import argparse
import keyword
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

# ---- a tokenizer and parser for the IDL subset both sides use ----------------------------------

_TOKEN = re.compile(r'''
    (?P<ws>\s+)
  | (?P<line_comment>//[^\n]*)
  | (?P<block_comment>/\*.*?\*/)
  | (?P<preproc>^[ \t]*\#[^\n]*)
  | (?P<string>L?"(?:\\.|[^"\\])*")
  | (?P<number>[-+]?(?:0[xX][0-9a-fA-F]+|\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?))
  | (?P<name>(?:::)?[A-Za-z_][A-Za-z0-9_]*(?:::[A-Za-z_][A-Za-z0-9_]*)*)
  | (?P<punct>[{}();<>,\[\]=@])
''', re.VERBOSE | re.MULTILINE | re.DOTALL)

# Multi-word IDL type names, spelled as the fixed-width names rosidl writes.
_TYPE_ALIASES = {
    'short': 'int16', 'unsigned short': 'uint16',
    'long': 'int32', 'unsigned long': 'uint32',
    'long long': 'int64', 'unsigned long long': 'uint64',
}


class IdlError(Exception):
    pass


def tokenize(text, origin):
    tokens = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            line = text.count('\n', 0, pos) + 1
            raise IdlError(f'{origin}:{line}: cannot read {text[pos:pos + 20]!r}')
        pos = m.end()
        if m.lastgroup in ('ws', 'line_comment', 'block_comment', 'preproc'):
            continue
        tokens.append(m.group())
    return tokens


def unescape(identifier):
    """IDL's escaped identifiers: `_INT8` names INT8 (used where a name collides with a keyword)."""
    return '::'.join(part[1:] if part.startswith('_') and not part.startswith('__') else part
                     for part in identifier.split('::'))


class Parser:
    """Collects structs, constants and typedefs, keyed by fully scoped name (`a::b::Name`)."""

    def __init__(self, tokens, origin):
        self.t = tokens
        self.i = 0
        self.origin = origin
        self.structs = {}    # scoped name -> [(field name, type tokens, array dims)]
        self.constants = {}  # scoped module name -> [(const name, type, value)]
        self.typedefs = {}   # scoped name -> (type tokens, array dims, module scope)

    def peek(self, k=0):
        return self.t[self.i + k] if self.i + k < len(self.t) else None

    def take(self, expected=None):
        tok = self.peek()
        if tok is None or (expected is not None and tok != expected):
            raise IdlError(f'{self.origin}: expected {expected!r}, found {tok!r} '
                           f'after {" ".join(self.t[max(0, self.i - 8):self.i])!r}')
        self.i += 1
        return tok

    def skip_annotation(self):
        self.take('@')
        self.take()
        if self.peek() == '(':
            depth = 0
            while True:
                tok = self.take()
                depth += tok == '('
                depth -= tok == ')'
                if depth == 0:
                    break

    def parse(self):
        self.definitions([])
        return self

    def definitions(self, scope):
        while self.peek() not in (None, '}'):
            tok = self.peek()
            if tok == '@':
                self.skip_annotation()
            elif tok == 'module':
                self.take()
                name = unescape(self.take())
                self.take('{')
                self.definitions(scope + [name])
                self.take('}')
                self.take(';')
            elif tok == 'struct':
                self.struct(scope)
            elif tok == 'const':
                self.const(scope)
            elif tok == 'typedef':
                self.take()
                type_tokens, name, dims = self.declaration()
                self.typedefs['::'.join(scope + [name])] = (type_tokens, dims, scope)
            else:
                raise IdlError(f'{self.origin}: unexpected {tok!r} in module {"::".join(scope)}')

    def struct(self, scope):
        self.take('struct')
        name = unescape(self.take())
        self.take('{')
        fields = []
        while self.peek() != '}':
            if self.peek() == '@':
                self.skip_annotation()
                continue
            type_tokens, field, dims = self.declaration()
            fields.append((field, type_tokens, dims, scope))
        self.take('}')
        self.take(';')
        self.structs['::'.join(scope + [name])] = fields

    def const(self, scope):
        self.take('const')
        type_tokens = []
        while self.peek(1) != '=':
            type_tokens.append(self.take())
        name = unescape(self.take())
        self.take('=')
        value = []
        while self.peek() != ';':
            value.append(self.take())
        self.take(';')
        module = '::'.join(scope)
        self.constants.setdefault(module, []).append(
            (name, ' '.join(type_tokens), ' '.join(value)))

    def declaration(self):
        """`TYPE NAME [N]... ;` -> (type tokens, name, [N, ...])."""
        tokens = []
        while self.peek() not in (';', '[', None):
            tokens.append(self.take())
        dims = []
        while self.peek() == '[':
            self.take('[')
            dims.append(self.take())
            self.take(']')
        self.take(';')
        if len(tokens) < 2:
            raise IdlError(f'{self.origin}: incomplete declaration {tokens!r}')
        return tokens[:-1], unescape(tokens[-1]), dims


# ---- types to one spelling ----------------------------------------------------------------------

PRIMITIVES = {'boolean', 'octet', 'char', 'wchar', 'float', 'double', 'long double', 'string',
              'wstring', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64', 'uint64'}


def canonical_type(tokens, scope, typedefs, wire_name):
    """Type tokens as one string: primitives by their fixed-width names, named types by their
    fully scoped wire name (`wire_name` maps a scoped name), typedefs resolved, arrays as [N]."""
    text = ' '.join(tokens)
    text = re.sub(r'\s*([<>,])\s*', r'\1', text)
    m = re.fullmatch(r'sequence<(.+?)(?:,(\w+))?>', text)
    if m:
        inner = canonical_type(m.group(1).split(' '), scope, typedefs, wire_name)
        return f'sequence<{inner}' + (f',{m.group(2)}' if m.group(2) else '') + '>'
    if re.fullmatch(r'w?string(<\w+>)?', text):
        return text
    text = _TYPE_ALIASES.get(text, text)
    if text in PRIMITIVES:
        return text
    # A named type: a typedef (looked up from the innermost scope outwards) or a struct.
    name = unescape(text)
    candidates = ([name.lstrip(':')] if name.startswith('::') else
                  ['::'.join(scope[:k] + [name]) for k in range(len(scope), -1, -1)])
    for candidate in candidates:
        if candidate in typedefs:
            base_tokens, dims, td_scope = typedefs[candidate]
            base = canonical_type(base_tokens, td_scope, typedefs, wire_name)
            return base + ''.join(f'[{d}]' for d in dims)
    if '::' not in name:
        name = '::'.join(scope + [name])
    return wire_name(name.lstrip(':'))


def dds_wire_name(scoped):
    """rosidl's `pkg::msg::Foo` -> the DDS wire name `pkg::msg::dds_::Foo_`."""
    parts = scoped.split('::')
    if len(parts) == 3 and parts[1] in ('msg', 'srv', 'action'):
        return f'{parts[0]}::{parts[1]}::dds_::{parts[2]}_'
    return scoped


def field_list(fields, typedefs, wire_name):
    return [(name, canonical_type(tokens, scope, typedefs, wire_name)
             + ''.join(f'[{d}]' for d in dims))
            for name, tokens, dims, scope in fields]


def literal(value):
    """A constant's value in one spelling (0x10 == 16, 1.50 == 1.5, TRUE)."""
    try:
        return repr(int(value, 0))
    except ValueError:
        pass
    try:
        return repr(float(value))
    except ValueError:
        return value.upper() if value.upper() in ('TRUE', 'FALSE') else value


def const_list(consts, typedefs, scope):
    return [(name, canonical_type(type_.split(' '), scope, typedefs, lambda n: n), literal(value))
            for name, type_, value in consts]


# ---- the two sides ------------------------------------------------------------------------------

class Definition:
    """One package's messages: {Msg: [(field, type)]} and {Msg: [(CONST, type, value)]}."""

    def __init__(self):
        self.fields = {}
        self.constants = {}

    def used_packages(self):
        """The packages whose types the fields name (from `pkg::msg::dds_::Type_`)."""
        return {m.group(1) for fields in self.fields.values() for _, type_ in fields
                for m in re.finditer(r'(\w+)::msg::dds_::', type_)}


def read_msgs(msg_dir, package, rosidl):
    """Translates every .msg with rosidl and reads the IDL it writes."""
    msgs = sorted(msg_dir.glob('*.msg'))
    if not msgs:
        raise IdlError(f'no .msg files in {msg_dir}')
    out = Definition()
    with tempfile.TemporaryDirectory(prefix='msg_idl_agreement.') as tmp:
        cmd = [rosidl, 'translate', '--to', 'idl', '-o', tmp, package]
        # `BASE:REL` makes rosidl write OUT/msg/Foo.idl whatever the absolute path of the .msg.
        cmd += [f'{msg_dir.parent}:{m.relative_to(msg_dir.parent)}' for m in msgs]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            raise IdlError(f'rosidl translate failed ({run.returncode}):\n{run.stdout}{run.stderr}')
        for m in msgs:
            idl_path = pathlib.Path(tmp) / 'msg' / (m.stem + '.idl')
            if not idl_path.exists():
                raise IdlError(f'rosidl translate wrote no {idl_path.name} for {m.name}:\n'
                               f'{run.stdout}{run.stderr}')
            p = Parser(tokenize(idl_path.read_text(), f'{m.name} (translated)'), m.name).parse()
            key = f'{package}::msg::{m.stem}'
            if key not in p.structs:
                raise IdlError(f'rosidl output for {m.name} has no struct {key}')
            out.fields[m.stem] = field_list(p.structs[key], p.typedefs, dds_wire_name)
            out.constants[m.stem] = const_list(
                p.constants.get(f'{key}_Constants', []), p.typedefs, [package, 'msg'])
    return out


def read_idl(idl_text, origin, package):
    """Reads tarmac's IDL: structs `pkg::msg::dds_::Foo_`, constants `pkg::msg::Foo_Constants`."""
    p = Parser(tokenize(idl_text, origin), origin).parse()
    out = Definition()
    problems = []
    for scoped, fields in p.structs.items():
        prefix = f'{package}::msg::dds_::'
        if not scoped.startswith(package + '::'):
            continue  # an included package's type
        if not (scoped.startswith(prefix) and scoped.endswith('_') and '::' not in scoped[len(prefix):]):
            problems.append(f'{origin}: struct {scoped} is not named {prefix}<Type>_ (ROS 2 wire name)')
            continue
        out.fields[scoped[len(prefix):-1]] = field_list(fields, p.typedefs, lambda n: n)
    for module, consts in p.constants.items():
        m = re.fullmatch(re.escape(package) + r'::msg::(\w+)_Constants', module)
        if not m:
            if module.startswith(package + '::'):
                problems.append(f'{origin}: constants in {module}, expected {package}::msg::<Type>_Constants')
            continue
        out.constants[m.group(1)] = const_list(consts, p.typedefs, module.split('::'))
    return out, problems


# ---- ROS 2 naming ---------------------------------------------------------------------------------

# Names a field cannot take: IDL keywords (rosidl's own IDL parser rejects them) and C++ and Python
# keywords (ROS 2's generated code would not compile or import).
_IDL_KEYWORDS = set('''abstract any alias attribute bitfield bitmask bitset boolean case char
  component connector const consumes context custom default double exception emits enum eventtype
  factory false finder fixed float getraises getter home import in inout interface local long
  manages map mirrorport module multiple native object octet oneway out primarykey private port
  porttype provides public publishes raises readonly setraises setter sequence short string
  struct supports switch true truncatable typedef typeid typename typeprefix unsigned union uses
  valuebase valuetype void wchar wstring int8 uint8 int16 int32 int64 uint16 uint32 uint64'''.split())
_CPP_KEYWORDS = set('''alignas alignof and and_eq asm auto bitand bitor bool break case catch char
  char8_t char16_t char32_t class compl concept const consteval constexpr constinit const_cast
  continue co_await co_return co_yield decltype default delete do double dynamic_cast else enum
  explicit export extern false float for friend goto if inline int long mutable namespace new
  noexcept not not_eq nullptr operator or or_eq private protected public register
  reinterpret_cast requires return short signed sizeof static static_assert static_cast struct
  switch template this thread_local throw true try typedef typeid typename union unsigned using
  virtual void volatile wchar_t while xor xor_eq'''.split())
RESERVED = _IDL_KEYWORDS | _CPP_KEYWORDS | {k.lower() for k in keyword.kwlist}


def naming_problems(reference):
    problems = []
    for msg, fields in reference.fields.items():
        if not re.fullmatch(r'[A-Z][A-Za-z0-9]*', msg):
            problems.append(f'{msg}.msg: message names are PascalCase')
        for name, _ in fields:
            if not re.fullmatch(r'[a-z][a-z0-9]*(_[a-z0-9]+)*', name):
                problems.append(f'{msg}.msg: field {name!r} is not snake_case')
            if name in RESERVED:
                problems.append(f'{msg}.msg: field {name!r} is a reserved word in IDL, C++ or Python')
        for name, _, _ in reference.constants.get(msg, []):
            if not re.fullmatch(r'[A-Z][A-Z0-9]*(_[A-Z0-9]+)*', name):
                problems.append(f'{msg}.msg: constant {name!r} is not UPPER_CASE')
    return problems


# ---- the comparison -----------------------------------------------------------------------------

def compare(reference, idl, idl_name):
    """Every difference between the .msg files (reference) and the IDL, as sentences."""
    diffs = []
    for msg in sorted(set(reference.fields) - set(idl.fields)):
        diffs.append(f'{msg}: in {msg}.msg, no struct {msg}_ in {idl_name}')
    for msg in sorted(set(idl.fields) - set(reference.fields)):
        diffs.append(f'{msg}: struct {msg}_ in {idl_name} has no {msg}.msg')
    for msg in sorted(set(reference.fields) & set(idl.fields)):
        want, have = reference.fields[msg], idl.fields[msg]
        want_types, have_types = dict(want), dict(have)
        for name, type_ in want:
            if name not in have_types:
                diffs.append(f'{msg}: field {name} ({type_}) missing from the IDL')
            elif have_types[name] != type_:
                diffs.append(f'{msg}: field {name} is {type_} in the .msg, {have_types[name]} in the IDL')
        for name, type_ in have:
            if name not in want_types:
                diffs.append(f'{msg}: field {name} ({type_}) in the IDL is not in the .msg')
        common_want = [n for n, _ in want if n in have_types]
        common_have = [n for n, _ in have if n in want_types]
        if common_want != common_have:
            diffs.append(f'{msg}: field order differs: .msg ({", ".join(common_want)}), '
                         f'IDL ({", ".join(common_have)})')
    for msg in sorted(set(reference.constants) | set(idl.constants)):
        want, have = reference.constants.get(msg, []), idl.constants.get(msg, [])
        if want == have:
            continue
        want_by, have_by = {c[0]: c for c in want}, {c[0]: c for c in have}
        for name, type_, value in want:
            if name not in have_by:
                diffs.append(f'{msg}: constant {name} ({type_} = {value}) missing from {msg}_Constants')
            elif have_by[name] != (name, type_, value):
                diffs.append(f'{msg}: constant {name} is {type_} = {value} in the .msg, '
                             f'{have_by[name][1]} = {have_by[name][2]} in the IDL')
        for name, type_, value in have:
            if name not in want_by:
                diffs.append(f'{msg}: constant {name} ({type_} = {value}) in the IDL is not in the .msg')
        common_want = [c[0] for c in want if c[0] in have_by]
        common_have = [c[0] for c in have if c[0] in want_by]
        if common_want != common_have:
            diffs.append(f'{msg}: constant order differs: .msg ({", ".join(common_want)}), '
                         f'IDL ({", ".join(common_have)})')
    return diffs


def package_problems(msg_dir, package, reference):
    """The ROS 2 package builds what it holds: CMakeLists.txt lists every .msg, and the packages
    the fields use are DEPENDENCIES there and <depend>s in package.xml."""
    problems = []
    cmake = msg_dir.parent / 'CMakeLists.txt'
    manifest = msg_dir.parent / 'package.xml'
    if not cmake.exists() or not manifest.exists():
        return [f'{msg_dir.parent}: no CMakeLists.txt or package.xml beside msg/']
    cmake_text = re.sub(r'#[^\n]*', '', cmake.read_text())
    listed = set(re.findall(r'"?msg/(\w+)\.msg"?', cmake_text))
    for msg in sorted(set(reference.fields) - listed):
        problems.append(f'CMakeLists.txt: msg/{msg}.msg is not in rosidl_generate_interfaces')
    for msg in sorted(listed - set(reference.fields)):
        problems.append(f'CMakeLists.txt: lists msg/{msg}.msg, which does not exist')
    m = re.search(r'DEPENDENCIES([^)]*)\)', cmake_text)
    cmake_deps = set(m.group(1).split()) if m else set()
    xml_deps = set(re.findall(r'<(?:build_)?depend>\s*(\w+)\s*</', manifest.read_text()))
    for dep in sorted(reference.used_packages() - {package}):
        if dep not in cmake_deps:
            problems.append(f'CMakeLists.txt: {dep} is used but not in DEPENDENCIES')
        if dep not in xml_deps:
            problems.append(f'package.xml: {dep} is used but not a <depend>')
    return problems


def check(msg_dir, idl_text, idl_name, package, rosidl):
    reference = read_msgs(msg_dir, package, rosidl)
    idl, problems = read_idl(idl_text, idl_name, package)
    return (naming_problems(reference) + package_problems(msg_dir, package, reference) + problems
            + compare(reference, idl, idl_name)), reference


# ---- self-test: mismatched copies must fail, naming the difference -------------------------------

# (what is changed, in the IDL text: old -> new, a word the report must contain)
_IDL_MUTATIONS = [
    ('a renamed field', 'uint64 cycle_index;', 'uint64 cycle_idx;', 'cycle_index'),
    ('a changed type', 'float wake_jitter_ms;', 'double wake_jitter_ms;', 'wake_jitter_ms is float'),
    ('two fields swapped', 'uint64 points_in;\n        uint64 points_used;',
     'uint64 points_used;\n        uint64 points_in;', 'field order differs'),
    ('a sequence made an array', 'sequence<tarmac_msgs::msg::dds_::InputAge_> input_ages;',
     'tarmac_msgs::msg::dds_::InputAge_ input_ages[4];', 'input_ages is sequence'),
    ('a bounded string', 'string config_hash;', 'string<64> config_hash;', 'config_hash'),
    ('an extra field', 'string config_hash;', 'string config_hash;\n        uint32 extra_count;',
     'extra_count'),
    ('a changed constant value', 'KIND_RESTRICTED = 4;', 'KIND_RESTRICTED = 5;', 'KIND_RESTRICTED'),
    ('a dropped constant', 'const uint8 KIND_FUEL_SPILL = 3;', '', 'KIND_FUEL_SPILL'),
    ('a struct without the wire suffix', 'struct InputAge_ {', 'struct InputAge {', 'InputAge'),
    ('a field of another type', 'std_msgs::msg::dds_::Header_ header;\n        sequence<',
     'std_msgs::msg::dds_::Time_ header;\n        sequence<', 'header is'),
]

# (what is changed, in the ROS 2 package: file, old -> new, a word the report must contain)
_PACKAGE_MUTATIONS = [
    ('a field added to a .msg', 'msg/ReasonCount.msg', 'uint64 total',
     'uint64 total\nuint64 peak', 'peak'),
    ('a reserved word as a field name', 'msg/InputAge.msg', 'bool stale',
     'bool stale\nbool class', 'reserved word'),
    ('a .msg left out of the build', 'CMakeLists.txt', '"msg/InputAge.msg"', '',
     'msg/InputAge.msg is not in rosidl_generate_interfaces'),
    ('a dependency left out of package.xml', 'package.xml', '<depend>geometry_msgs</depend>', '',
     'geometry_msgs is used but not a <depend>'),
]


def self_test(msg_dir, idl_text, idl_name, package, rosidl):
    failures = []
    diffs, _ = check(msg_dir, idl_text, idl_name, package, rosidl)
    if diffs:
        failures.append('the unchanged files must agree, but:\n    ' + '\n    '.join(diffs))
    for what, old, new, expect in _IDL_MUTATIONS:
        if old not in idl_text:
            failures.append(f'{what}: {old!r} is no longer in {idl_name}; update the self-test')
            continue
        diffs, _ = check(msg_dir, idl_text.replace(old, new, 1), idl_name, package, rosidl)
        report(what, diffs, expect, failures)
    for what, file, old, new, expect in _PACKAGE_MUTATIONS:
        with tempfile.TemporaryDirectory(prefix='msg_idl_agreement.self.') as tmp:
            copy = pathlib.Path(tmp) / package
            shutil.copytree(msg_dir.parent, copy)
            text = (copy / file).read_text()
            if old not in text:
                failures.append(f'{what}: {old!r} is no longer in {file}; update the self-test')
                continue
            (copy / file).write_text(text.replace(old, new, 1))
            diffs, _ = check(copy / 'msg', idl_text, idl_name, package, rosidl)
            report(what, diffs, expect, failures)
    if failures:
        print('self-test FAILED:\n  ' + '\n  '.join(failures))
        return 1
    print(f'self-test passed: the unchanged files agree and all '
          f'{len(_IDL_MUTATIONS) + len(_PACKAGE_MUTATIONS)} mismatched copies were caught')
    return 0


def report(what, diffs, expect, failures):
    if not diffs:
        failures.append(f'{what}: not detected')
    elif not any(expect in d for d in diffs):
        failures.append(f'{what}: detected, but no difference mentions {expect!r}: {diffs}')
    else:
        print(f'caught {what}: ' + '; '.join(diffs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--msg-dir', required=True, type=pathlib.Path, help='the package\'s msg/ folder')
    ap.add_argument('--idl', required=True, type=pathlib.Path, help='the DDS IDL file to check')
    ap.add_argument('--package', help='ROS 2 package name (default: the msg folder\'s parent name)')
    ap.add_argument('--rosidl', default=shutil.which('rosidl'), help='the rosidl command')
    ap.add_argument('--self-test', action='store_true',
                    help='check that mismatched copies of the IDL and .msg files are caught')
    args = ap.parse_args()
    if not args.rosidl:
        print('msg_idl_agreement: `rosidl` not found; install rosidl-tools python3-catkin-pkg '
              'python3-empy (tools/install-deps.sh)', file=sys.stderr)
        return 2
    msg_dir = args.msg_dir.resolve()
    package = args.package or msg_dir.parent.name
    idl_text = args.idl.read_text()
    try:
        if args.self_test:
            return self_test(msg_dir, idl_text, args.idl.name, package, args.rosidl)
        diffs, reference = check(msg_dir, idl_text, args.idl.name, package, args.rosidl)
    except IdlError as e:
        print(f'msg_idl_agreement: {e}', file=sys.stderr)
        return 2
    if diffs:
        print(f'{args.idl} does not match {msg_dir} ({len(diffs)} difference(s)); '
              f'the .msg files are the reference:')
        for d in diffs:
            print(f'  {d}')
        return 1
    print(f'{args.idl.name} agrees with {len(reference.fields)} .msg files in {msg_dir} '
          f'(fields, types, order, constants)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
