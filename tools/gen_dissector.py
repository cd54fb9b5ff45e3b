"""Generate dissectors/manip.lua, a Wireshark dissector for CHUDP, Chaos packets and the manip protocol.

    python tools/gen_dissector.py            # rewrite dissectors/manip.lua
    python tools/gen_dissector.py --check    # exit 1 if it is stale

Everything the protocol says is taken from the spec data (opcodes, names, layouts, field types,
severities, error codes, asynchronous conditions, Chaos opcodes) and from the Lisp Machine character
set of :mod:`manip.codecs.lispm_text`; the Lua below is only the machinery that walks them.  Field
names follow ``manip-decode``'s tree (a label ``request number`` is ``manip.request_number``), so the
test that runs tshark compares the two field for field (tests/decode/test_dissector.py).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from manip.codecs.lispm_text import PRIVATE_BASE, PRIVATE_CODES
from manip.spec import SPEC, Layout

TARGET = Path(__file__).resolve().parents[1] / "dissectors" / "manip.lua"

# Fields of the manip tree that are not request or reply fields of the spec, with their Lua types.
FIXED_FIELDS: dict[str, tuple[str, str]] = {
    "opcode": ("uint8", "Opcode"),
    "name": ("string", "Request"),
    "hazard": ("string", "Hazard class"),
    "request_number": ("uint16", "Request number"),
    "data": ("string", "Data (hex)"),
    "where": ("string", "Where"),
    "severity": ("string", "Severity"),
    "code": ("string", "Error code"),
    "message": ("string", "Message"),
    "arguments": ("uint16", "Argument"),
    "rendered": ("string", "Rendered"),
    "condition": ("uint16", "Condition"),
    "layout": ("string", "Asynchronous layout"),
    "action": ("uint16", "Action"),
    "guard": ("uint16", "Guard"),
    "reserved": ("uint16", "Reserved"),
    "segment": ("uint16", "Segment"),
    "word_3": ("uint16", "Word 3"),
    "decode_error": ("string", "Decode error"),
    "clause": ("string", "Clause broken"),
}
_ELEMENT_TYPES = {
    "float": "double",
    "word": "uint16",
    "small": "uint16",
    "counted": "uint16",
    "int16": "int16",
    "text": "string",
}


def _lua_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif 32 <= ord(ch) < 127:
            out.append(ch)
        else:
            out.append("".join(f"\\{b}" for b in ch.encode()))
    return '"' + "".join(out) + '"'


def _layout(layout: Layout) -> str:
    fields = ", ".join(
        f"{{{_lua_string(f.name)}, {_lua_string(f.type.element)}, {f.type.count or 0}}}"
        for f in layout.fields
    )
    return "{" + fields + "}"


def _field_types() -> dict[str, tuple[str, str]]:
    types: dict[str, tuple[str, str]] = dict(FIXED_FIELDS)
    for op in SPEC.requests.values():
        for f in (*op.request.fields, *op.response.data.fields):
            kind = _ELEMENT_TYPES[f.type.element]
            title = f.name.replace("_", " ").capitalize()
            if f.name in types and types[f.name][0] != kind:
                raise SystemExit(f"field {f.name!r} has two types: {types[f.name][0]} and {kind}")
            types.setdefault(f.name, (kind, title))
    return types


def tables() -> str:
    """The Lua tables generated from the spec."""
    lines = [f"local SPEC_REVISION = {_lua_string(SPEC.revision)}", "", "local CHAOS_OPCODES = {"]
    lines += [
        f"  [{o.value}] = {_lua_string(o.name)}," for o in SPEC.chaos_opcodes.values() if o.value < 0o200
    ]
    lines += ["}", "", "local REQUESTS = {"]
    for op in SPEC.requests.values():
        lines.append(
            f"  [{op.opcode}] = {{name = {_lua_string(op.name)}, title = {_lua_string(op.title)}, "
            f"hazard = {_lua_string(op.hazard)}, extension = {str(op.extension).lower()}, "
            f"request = {_layout(op.request)}, "
            f"kind = {_lua_string(op.response.form)}, response = {_layout(op.response.data)}}},"
        )
    lines += ["}", "", "local SERVER_OPCODES = {"]
    lines += [f"  [{s.opcode}] = {_lua_string(s.name)}," for s in SPEC.server_opcodes.values()]
    lines += ["}", "", "local SEVERITIES = {"]
    lines += [f"  [{_lua_string(s.letter)}] = {_lua_string(s.meaning)}," for s in SPEC.severities.values()]
    lines += ["}", "", "local ERROR_CODES = {"]
    lines += [f"  [{_lua_string(c.code)}] = {_lua_string(c.meaning)}," for c in SPEC.error_codes.values()]
    lines += ["}", "", "local ASYNC_CONDITIONS = {"]
    lines += [f"  [{a.code}] = {_lua_string(a.name)}," for a in SPEC.async_codes.values()]
    lines += ["}", "", "-- Lisp Machine codes shown as private-use characters (manip.codecs.lispm_text)."]
    lines += ["local LISPM_PRIVATE = {"]
    private = sorted(PRIVATE_CODES)
    for i in range(0, len(private), 16):
        lines.append("  " + " ".join(f"[{c}] = true," for c in private[i : i + 16]))
    lines += ["}", f"local LISPM_PRIVATE_BASE = {PRIVATE_BASE}", "", "local MANIP_FIELD_TYPES = {"]
    for name, (kind, title) in sorted(_field_types().items()):
        lines.append(f"  [{_lua_string(name)}] = {{{_lua_string(kind)}, {_lua_string(title)}}},")
    lines.append("}")
    return "\n".join(lines)


HEADER = """\
-- manip.lua: a Wireshark dissector for Chaosnet over UDP (CHUDP), the Chaos packet and the Chaos
-- manipulator protocol of the 1985 Implementor's Guide (requests 0200-0221, manip's 0240-0261).
--
-- GENERATED by tools/gen_dissector.py from the manip spec data: do not edit; run the tool again.
--
--   wireshark -X lua_script:dissectors/manip.lua capture.pcapng
--   tshark -X lua_script:dissectors/manip.lua -r capture.pcapng -V
--
-- CHUDP datagrams are found on UDP port 42042 and, by their header, on any other port.  A packet
-- whose source sent an RFC is a request; in a capture that starts after the connection opened, the
-- sides are told by the UDP ports and by the shape of the first data packet.  The replies are decoded
-- by the layout of the request they answer (found by its packet number).  Floats are PDP-11 F floats
-- shown as numbers; error strings are split into where, severity, code and message with their
-- arguments; describe-self text is shown as text.  Field names follow manip-decode's
-- (manip.request_number, manip.joints, ...).  It runs on Lua 5.2 to 5.4.
"""

BODY = r"""
-- Bit operations by arithmetic, so that one file runs on every Lua Wireshark is built with: Lua 5.2
-- (bit32, no bitwise operators: they would not even parse) and Lua 5.3/5.4 (operators, no bit32).
-- Every value here is a non-negative integer below 2^32.
local POW2 = {}
do local p = 1 for i = 0, 32 do POW2[i] = p p = p * 2 end end
local function shr(v, n) return math.floor(v / POW2[n]) end     -- v >> n
local function low(v, n) return v % POW2[n] end                 -- v & (2^n - 1)
local function has_bit(v, b) return shr(v, b) % 2 == 1 end      -- v & (1 << b) ~= 0

-- ------------------------------------------------------------------------------ protocols and fields

local p_chudp = Proto("chudp", "Chaos over UDP (CHUDP)")
local p_chaos = Proto("chaos", "Chaosnet packet")
local p_manip = Proto("manip", "Chaos manipulator protocol (" .. SPEC_REVISION .. ")")

local f_chudp = {
  version = ProtoField.uint8("chudp.version", "Version"),
  ["function"] = ProtoField.uint8("chudp.function", "Function"),
  arguments = ProtoField.bytes("chudp.arguments", "Arguments"),
}
p_chudp.fields = {f_chudp.version, f_chudp["function"], f_chudp.arguments}

local f_chaos = {
  opcode = ProtoField.uint8("chaos.opcode", "Opcode", base.OCT),
  fc = ProtoField.uint8("chaos.fc", "Forwarding count"),
  nbytes = ProtoField.uint16("chaos.nbytes", "Data bytes"),
  destination_host = ProtoField.uint16("chaos.destination_host", "Destination host", base.OCT),
  destination_index = ProtoField.uint16("chaos.destination_index", "Destination index", base.OCT),
  source_host = ProtoField.uint16("chaos.source_host", "Source host", base.OCT),
  source_index = ProtoField.uint16("chaos.source_index", "Source index", base.OCT),
  packet_number = ProtoField.uint16("chaos.packet_number", "Packet number"),
  ack_number = ProtoField.uint16("chaos.ack_number", "Ack number"),
  trailer_dest = ProtoField.uint16("chaos.trailer_dest", "Hardware destination", base.OCT),
  trailer_source = ProtoField.uint16("chaos.trailer_source", "Hardware source", base.OCT),
  trailer_checksum = ProtoField.uint16("chaos.trailer_checksum", "Checksum", base.HEX),
  contact = ProtoField.string("chaos.contact", "Contact"),
  arguments = ProtoField.string("chaos.arguments", "Arguments"),
  receipt = ProtoField.uint16("chaos.receipt", "Receipt"),
  window = ProtoField.uint16("chaos.window", "Window"),
  text = ProtoField.string("chaos.text", "Text"),
  new_host = ProtoField.uint16("chaos.new_host", "New host", base.OCT),
  data = ProtoField.string("chaos.data", "Data (hex)"),
}
local chaos_list = {}
for _, f in pairs(f_chaos) do chaos_list[#chaos_list + 1] = f end
p_chaos.fields = chaos_list

local f_manip = {}
local manip_list = {}
for name, spec in pairs(MANIP_FIELD_TYPES) do
  local kind, title = spec[1], spec[2]
  local abbrev = "manip." .. name
  local f
  if kind == "double" then f = ProtoField.double(abbrev, title)
  elseif kind == "string" then f = ProtoField.string(abbrev, title)
  elseif kind == "int16" then f = ProtoField.int16(abbrev, title)
  elseif kind == "uint8" then f = ProtoField.uint8(abbrev, title, base.OCT)
  else f = ProtoField.uint16(abbrev, title) end
  f_manip[name] = f
  manip_list[#manip_list + 1] = f
end
p_manip.fields = manip_list

local e_malformed = ProtoExpert.new("manip.malformed", "Malformed manip packet", expert.group.MALFORMED,
                                    expert.severity.ERROR)
local e_checksum = ProtoExpert.new("chaos.bad_checksum", "Bad CHUDP checksum", expert.group.CHECKSUM,
                                   expert.severity.ERROR)
p_manip.experts = {e_malformed}
p_chaos.experts = {e_checksum}

-- ------------------------------------------------------------------------------ helpers

local function octal(v)
  if v == 0 then return "0" end
  return string.format("0%o", v)
end

local function u16(data, i)  -- a little-endian word of the natural-order data
  return data:get_index(i) + data:get_index(i + 1) * 256
end

local function utf8(cp)
  if cp < 0x80 then return string.char(cp) end
  if cp < 0x800 then
    return string.char(0xC0 + shr(cp, 6), 0x80 + low(cp, 6))
  end
  return string.char(0xE0 + shr(cp, 12), 0x80 + low(shr(cp, 6), 6), 0x80 + low(cp, 6))
end

local LISPM_FORMATTING = {[0x88] = "\b", [0x89] = "\t", [0x8A] = "\n", [0x8C] = "\f", [0x8D] = "\n"}

local function lispm(data, first, count)  -- Lisp Machine text to UTF-8
  local out = {}
  for i = first, first + count - 1 do
    local c = data:get_index(i)
    if LISPM_FORMATTING[c] then out[#out + 1] = LISPM_FORMATTING[c]
    elseif LISPM_PRIVATE[c] then out[#out + 1] = utf8(LISPM_PRIVATE_BASE + c)
    else out[#out + 1] = string.char(c) end
  end
  return table.concat(out)
end

local function ascii(data, first, count)  -- bytes as ASCII, anything else the replacement character
  local out = {}
  for i = first, first + count - 1 do
    local c = data:get_index(i)
    out[#out + 1] = c < 0x80 and string.char(c) or "\239\191\189"
  end
  return table.concat(out)
end

local function hex(data, first, count)
  local out = {}
  for i = first, first + count - 1 do out[#out + 1] = string.format("%02x", data:get_index(i)) end
  return table.concat(out)
end

local function pdp11_float(data, i)  -- a PDP-11 F float: nil and a reason for a reserved operand
  local w0, w1 = u16(data, i), u16(data, i + 2)
  local exp = low(shr(w0, 7), 8)
  local negative = has_bit(w0, 15)
  if exp == 0 then
    if negative then return nil, "float.reserved-operand" end
    return 0.0
  end
  local v = (low(w0, 7) * 65536 + w1 + 8388608) * 2 ^ (exp - 152)
  if negative then v = -v end
  return v
end

local function fmt_number(v)
  if v == math.floor(v) and math.abs(v) < 1e15 then return string.format("%.1f", v) end
  return string.format("%.9g", v)
end

local function joint_mask(mask)
  local joints = {}
  for b = 0, 15 do
    if has_bit(mask, b) then joints[#joints + 1] = tostring(b + 1) end
  end
  if #joints == 0 then return "none" end
  if #joints == 1 then return joints[1] end
  return table.concat(joints, ", ", 1, #joints - 1) .. " and " .. joints[#joints]
end

local ELEMENT_SIZE = {float = 4, word = 2, small = 2, int16 = 2}

-- ------------------------------------------------------------------------------ layouts

-- Check data[start..] against a layout as manip's codecs do; returns nil or (message, clause), and
-- whether a one-byte "small" field was sent.
local function check_length(layout, data, start, what, clause)
  local body = data:len() - start
  local size, has_small, variable = 0, false, false
  for _, f in ipairs(layout) do
    local element, count = f[2], f[3]
    if element == "small" then has_small = true end
    if count == 0 or element == "counted" or element == "text" then variable = true
    else size = size + ELEMENT_SIZE[element] * count end
  end
  if not variable then
    if has_small and body == size - 1 then return nil, nil, true end
    if body ~= size then
      return string.format("%s needs %d data bytes after offset %d, got %d", what, size, start, body), clause
    end
    return nil
  end
  for _, f in ipairs(layout) do
    if f[2] == "counted" then
      if body < 2 then return what .. "." .. f[1] .. ": missing word count", clause end
      local n = u16(data, start)
      if body ~= 2 + 2 * n then
        return string.format("%s.%s: count says %d words (%d bytes), %d bytes present", what, f[1], n,
                             2 + 2 * n, body), clause
      end
    end
  end
  return nil
end

-- Add the fields of a layout; returns nil, or (message, clause) for a value that does not decode.
local function add_layout(tree, layout, data, dtvb, start, short_small)
  local at = start
  for _, f in ipairs(layout) do
    local name, element, count = f[1], f[2], f[3]
    local field = f_manip[name]
    if element == "float" then
      local values = {}
      for k = 0, count - 1 do
        local v, problem = pdp11_float(data, at + 4 * k)
        if v == nil then return "reserved operand in " .. name, problem end
        values[#values + 1] = v
      end
      local label = {}
      for k, v in ipairs(values) do label[k] = fmt_number(v) end
      local sub = tree
      if count > 1 then
        sub = tree:add(dtvb(at, 4 * count), name .. ": (" .. table.concat(label, ", ") .. ")")
      end
      for k, v in ipairs(values) do sub:add(field, dtvb(at + 4 * (k - 1), 4), v) end
      at = at + 4 * count
    elseif element == "small" then
      local size = short_small and 1 or 2
      local v = short_small and data:get_index(at) or u16(data, at)
      tree:add(field, dtvb(at, size), v)
      at = at + size
    elseif element == "word" or element == "int16" then
      local sub = tree
      if count > 1 then sub = tree:add(dtvb(at, 2 * count), name) end
      for k = 0, count - 1 do
        local v = u16(data, at + 2 * k)
        if element == "int16" and v >= 0x8000 then v = v - 0x10000 end
        sub:add(field, dtvb(at + 2 * k, 2), v)
      end
      at = at + 2 * count
    elseif element == "counted" then
      local n = u16(data, at)
      local sub = tree:add(dtvb(at, 2 + 2 * n), string.format("%s: %d words", name, n))
      for k = 1, n do sub:add(field, dtvb(at + 2 * k, 2), u16(data, at + 2 * k)) end
      at = at + 2 + 2 * n
    elseif element == "text" then
      local count_left = data:len() - at
      if count_left > 0 then tree:add(field, dtvb(at, count_left), lispm(data, at, count_left)) end
      at = data:len()
    end
  end
  return nil
end

local function decode_error(tree, message, clause)
  local item = tree:add(f_manip.decode_error, message)
  if clause then tree:add(f_manip.clause, clause) end
  item:add_proto_expert_info(e_malformed, message)
end

-- ------------------------------------------------------------------------------ server packets

local function error_string(tree, data, dtvb)
  -- where: severity code message, then optionally NUL and 16-bit numbers (erratum error-arg-layout)
  local n = data:len()
  local nul = nil
  for i = 2, n - 1 do if data:get_index(i) == 0 then nul = i break end end
  local text_end = nul or n
  local text = lispm(data, 2, text_end - 2)
  local sep = string.find(text, ": ", 1, true)
  if not sep then return "no ': ' separating where from the severity", "error-string.format" end
  local where = string.sub(text, 1, sep - 1)
  local rest = string.sub(text, sep + 2)
  local space = string.find(rest, " ", 1, true)
  local severity = space and string.sub(rest, 1, space - 1) or rest
  if severity == "" then return "missing severity", "error-string.format" end
  if not space then return "missing error code", "error-string.format" end
  rest = string.sub(rest, space + 1)
  space = string.find(rest, " ", 1, true)
  local code = space and string.sub(rest, 1, space - 1) or rest
  if code == "" then return "missing error code", "error-string.format" end
  local message = space and string.sub(rest, space + 1) or ""
  local args = {}
  if nul then
    local pos = nul + 1
    if (n - pos) % 2 == 1 then  -- an odd count after the NUL: a pad byte first
      if data:get_index(pos) ~= 0 then return "pad byte before the numbers is not zero",
                                              "error-string.arg-layout" end
      pos = pos + 1
    end
    if (n - pos) % 2 == 1 then
      return "numbers after the NUL are not whole words", "error-string.args"
    end
    for i = pos, n - 2, 2 do args[#args + 1] = {u16(data, i), i} end
  end
  local rendered = message
  if nul then
    local out, k = {}, 1
    for ch in string.gmatch(message, ".") do
      if (ch == "~" or ch == "$") and args[k] then
        out[#out + 1] = ch == "~" and tostring(args[k][1]) or joint_mask(args[k][1])
        k = k + 1
      else out[#out + 1] = ch end
    end
    rendered = table.concat(out)
  end
  local head = where .. ": " .. severity .. " " .. code
  rendered = rendered ~= "" and head .. " " .. rendered or head
  tree:add(f_manip.where, dtvb(2, sep - 1), where)
  local meaning = SEVERITIES[severity] or "unknown severity"
  tree:add(f_manip.severity, severity):append_text(" (" .. meaning .. ")")
  meaning = ERROR_CODES[code] or "not a code of the spec"
  tree:add(f_manip.code, code):append_text(" (" .. meaning .. ")")
  tree:add(f_manip.message, message)
  for _, a in ipairs(args) do tree:add(f_manip.arguments, dtvb(a[2], 2), a[1]) end
  tree:add(f_manip.rendered, rendered)
  return nil, nil, rendered
end

local function response_layout(op)
  if op.kind == "done" then return {} end
  if op.kind == "segment" then return {{"segment", "word", 1}} end
  return op.response
end

local CLAUSE_OF_KIND = {done = "response.done-empty", segment = "response.segment-number",
                        data = "response.data-layout", multi = "response.data-layout"}

local function server_packet(tree, wire, opcode, data, dtvb, op)
  local n = data:len()
  local name = SERVER_OPCODES[opcode]
  local root = tree:add(p_manip, wire, "Server packet " .. octal(opcode) .. " " .. name)
  root:add(f_manip.opcode, opcode)
  if n < 2 then
    decode_error(root, "no request number", "response.echoes-request-number")
    return
  end
  local number = u16(data, 0)
  if opcode == 0x83 then  -- asynchronous response: 8 bytes (number first) or the 1985 guide's 6
    if n ~= 8 and n ~= 6 then
      decode_error(root, string.format(
        "asynchronous response needs 8 data bytes (or the 1985 guide's 6), got %d", n), "async.layout")
      return
    end
    local at = 0
    if n == 8 then
      root:add(f_manip.layout, "numbered")
      root:add(f_manip.request_number, dtvb(0, 2), number)
      at = 2
    else
      root:add(f_manip.layout, "guide")
      root:append_text(" (the 1985 guide's layout: no request number)")
    end
    local condition, w2, w3 = u16(data, at), u16(data, at + 2), u16(data, at + 4)
    root:add(f_manip.condition, dtvb(at, 2), condition):append_text(
      " (" .. (ASYNC_CONDITIONS[condition] or ("unknown-" .. condition)) .. ")")
    if condition == 1 then
      root:add(f_manip.action, dtvb(at + 2, 2), w2)
      root:add(f_manip.guard, dtvb(at + 4, 2), w3)
    else
      root:add(f_manip.reserved, dtvb(at + 2, 2), w2)
      root:add(condition == 2 and f_manip.segment or f_manip.word_3, dtvb(at + 4, 2), w3)
    end
    root:append_text(": " .. (ASYNC_CONDITIONS[condition] or ("unknown-" .. condition)))
    return
  end
  if opcode ~= 0x80 then  -- an error string
    root:add(f_manip.request_number, dtvb(0, 2), number)
    local problem, clause, rendered = error_string(root, data, dtvb)
    if problem then decode_error(root, problem, clause) return end
    root:append_text(": " .. rendered)
    return
  end
  root:add(f_manip.request_number, dtvb(0, 2), number)
  if op == nil then
    if n > 2 then root:add(f_manip.data, dtvb(2, n - 2), hex(data, 2, n - 2)) end
    root:append_text(" to request " .. number)
    return
  end
  root:append_text(" to request " .. number .. " (" .. op.name .. ", " .. op.kind .. " reply)")
  if op.kind == "multi" then
    if n > 2 then root:add(f_manip.text, dtvb(2, n - 2), lispm(data, 2, n - 2))
    else root:append_text(": end") end
    return
  end
  local layout = response_layout(op)
  local message, clause, short = check_length(layout, data, 2, op.name .. ".reply", CLAUSE_OF_KIND[op.kind])
  if message then decode_error(root, message, clause) return end
  message, clause = add_layout(root, layout, data, dtvb, 2, short)
  if message then decode_error(root, message, clause) end
end

local function request(tree, wire, opcode, data, dtvb)
  local op = REQUESTS[opcode]
  if op == nil then
    local root = tree:add(p_manip, wire, "Request " .. octal(opcode) .. ": not a request opcode of the spec")
    decode_error(root, "opcode " .. octal(opcode) .. " is not a request opcode of the spec",
                 "request.unknown-opcode")
    return nil
  end
  local root = tree:add(p_manip, wire, "Request " .. octal(opcode) .. " " .. op.name .. ": " .. op.title)
  root:add(f_manip.opcode, opcode)
  root:add(f_manip.name, op.name)
  root:add(f_manip.hazard, op.hazard)
  local message, clause, short = check_length(op.request, data, 0, op.name, "request.data-length")
  if message then decode_error(root, message, clause) return op end
  message, clause = add_layout(root, op.request, data, dtvb, 0, short)
  if message then decode_error(root, message, clause) end
  return op
end

-- ------------------------------------------------------------------------------ conversations

-- Which side is the server: the one an RFC goes to; the one an OPN or ANS comes from; in a capture that
-- starts after the connection opened, the one whose UDP port is CHUDP's when the other's is not, else
-- the one the first data packet goes to when its shape is a request's (from when its shape is a server
-- packet's), as manip-decode --pcap decides.  A side once known stays known.
local clients = {}   -- "host:index" of each client: its data packets are requests
local servers = {}   -- "host:index" of each server: its data packets are server packets
local pending = {}   -- "host:index#packet" of a request -> its opcode
local CHUDP_PORT = 42042

local function key(host, index) return host .. ":" .. index end

local function looks_like_error(data)  -- a request number, then "where: SEVERITY CODE ..."
  local n = data:len()
  if n < 4 then return false end
  local stop = n
  for i = 2, n - 1 do if data:get_index(i) == 0 then stop = i break end end
  return string.find(lispm(data, 2, stop - 2), "^[^:]*: %S+ %S") ~= nil
end

local function guess_is_request(opcode, data)  -- by shape, as manip-decode guesses
  if opcode > 0x85 or data:len() == 0 then return true end
  if opcode == 0x80 or opcode == 0x83 then return false end
  return not looks_like_error(data)
end

local function is_request(pinfo, opcode, data, sh, si, dh, di)
  local src, dst = key(sh, si), key(dh, di)
  if clients[src] or servers[dst] then return true end
  if clients[dst] or servers[src] then return false end
  local request
  if pinfo.src_port == CHUDP_PORT and pinfo.dst_port ~= CHUDP_PORT then request = false
  elseif pinfo.dst_port == CHUDP_PORT and pinfo.src_port ~= CHUDP_PORT then request = true
  else request = guess_is_request(opcode, data) end
  if request then clients[src], servers[dst] = true, true
  else clients[dst], servers[src] = true, true end
  return request
end

-- ------------------------------------------------------------------------------ the packet

local function control(tree, opcode, data, dtvb, ack)
  local n = data:len()
  if opcode == 1 then  -- RFC
    local text = ascii(data, 0, n)
    local space = string.find(text, " ", 1, true)
    local contact = space and string.sub(text, 1, space - 1) or text
    if dtvb then tree:add(f_chaos.contact, dtvb(0, #contact), contact)
    else tree:add(f_chaos.contact, contact) end
    if space and space < #text then tree:add(f_chaos.arguments, string.sub(text, space + 1)) end
    return "contact " .. contact
  elseif (opcode == 2 or opcode == 7) and n >= 4 then  -- OPN, STS
    tree:add(f_chaos.receipt, dtvb(0, 2), u16(data, 0))
    tree:add(f_chaos.window, dtvb(2, 2), u16(data, 2))
    return "receipt " .. u16(data, 0) .. " window " .. u16(data, 2)
  elseif opcode == 3 or opcode == 9 or opcode == 5 or opcode == 4 then  -- CLS, LOS, ANS, FWD
    local text = lispm(data, 0, n)
    tree:add(f_chaos.text, text)
    if opcode == 4 then tree:add(f_chaos.new_host, ack) end
    return text
  elseif n > 0 then
    tree:add(f_chaos.data, dtvb(0, n), hex(data, 0, n))
  end
  return nil
end

local function opcode_name(opcode)
  if opcode >= 0xC0 then return "DWD" end
  if opcode >= 0x80 then return "DAT" end
  return CHAOS_OPCODES[opcode] or "illegal"
end

function p_chudp.dissector(tvb, pinfo, tree)
  local size = tvb:len()
  if size < 26 or tvb(0, 1):uint() ~= 1 or tvb(1, 1):uint() ~= 1 or size % 2 == 1 then return 0 end
  pinfo.cols.protocol = "CHUDP"
  local t_chudp = tree:add(p_chudp, tvb(0, 4))
  t_chudp:add(f_chudp.version, tvb(0, 1))
  t_chudp:add(f_chudp["function"], tvb(1, 1))
  t_chudp:add(f_chudp.arguments, tvb(2, 2))

  -- The Chaos header: eight words, most significant byte first.
  local w = function(i) return tvb(4 + 2 * i, 2):uint() end
  local opcode = shr(w(0), 8)
  local fc, nbytes = shr(w(1), 12), low(w(1), 12)
  local dh, di, sh, si, pn, an = w(2), w(3), w(4), w(5), w(6), w(7)
  local padded = nbytes + nbytes % 2
  local t = tree:add(p_chaos, tvb(4, size - 4))
  t:add(f_chaos.opcode, tvb(4, 1), opcode):append_text(" (" .. opcode_name(opcode) .. ")")
  t:add(f_chaos.fc, tvb(6, 1), fc)
  t:add(f_chaos.nbytes, tvb(6, 2), nbytes)
  t:add(f_chaos.destination_host, tvb(8, 2), dh)
  t:add(f_chaos.destination_index, tvb(10, 2), di)
  t:add(f_chaos.source_host, tvb(12, 2), sh)
  t:add(f_chaos.source_index, tvb(14, 2), si)
  t:add(f_chaos.packet_number, tvb(16, 2), pn)
  t:add(f_chaos.ack_number, tvb(18, 2), an)
  if 20 + padded + 6 ~= size then
    t:add_proto_expert_info(e_checksum, "nbytes does not fill the datagram")
    return size
  end
  local tr = 20 + padded
  t:add(f_chaos.trailer_dest, tvb(tr, 2))
  t:add(f_chaos.trailer_source, tvb(tr + 2, 2))
  local sum = 0
  for i = 4, size - 2, 2 do sum = sum + tvb(i, 2):uint() end
  while sum > 0xFFFF do sum = low(sum, 16) + shr(sum, 16) end
  local ck = t:add(f_chaos.trailer_checksum, tvb(tr + 4, 2))
  if sum ~= 0xFFFF then ck:add_proto_expert_info(e_checksum) end
  t:append_text(string.format(", %s %s, host %s index %s -> host %s index %s, #%d", opcode_name(opcode),
                              octal(opcode), octal(sh), octal(si), octal(dh), octal(di), pn))

  -- The data, un-swapped into the order a PDP-11 holds them (first byte low in each word).
  local data = ByteArray.new()
  data:set_size(padded)
  for k = 0, padded / 2 - 1 do
    data:set_index(2 * k, tvb(20 + 2 * k + 1, 1):uint())
    data:set_index(2 * k + 1, tvb(20 + 2 * k, 1):uint())
  end
  data:set_size(nbytes)
  local dtvb = nil
  if nbytes > 0 then dtvb = data:tvb("Chaos data (PDP-11 byte order)") end

  local info
  if opcode < 0x80 then
    if opcode == 1 then clients[key(sh, si)] = true end
    if opcode == 2 or opcode == 5 then servers[key(sh, si)], clients[key(dh, di)] = true, true end
    info = control(t, opcode, data, dtvb, an)
    pinfo.cols.info = (CHAOS_OPCODES[opcode] or octal(opcode)) .. (info and (" " .. info) or "")
    return size
  end
  if opcode >= 0xC0 then
    pinfo.cols.info = "DWD " .. octal(opcode)
    return size
  end
  pinfo.cols.protocol = "manip"
  local wire = tvb(4, size - 4)
  if is_request(pinfo, opcode, data, sh, si, dh, di) then
    local op = request(tree, wire, opcode, data, dtvb)
    if op and not pinfo.visited then pending[key(sh, si) .. "#" .. pn] = op end
    pinfo.cols.info = "request " .. (op and op.name or octal(opcode)) .. " #" .. pn
  else
    local op = nil
    if opcode == 0x80 and nbytes >= 2 then op = pending[key(dh, di) .. "#" .. u16(data, 0)] end
    if SERVER_OPCODES[opcode] == nil then
      tree:add(p_manip, wire, "Data " .. octal(opcode) .. ": not a server opcode")
    else
      server_packet(tree, wire, opcode, data, dtvb, op)
    end
    pinfo.cols.info = (SERVER_OPCODES[opcode] or octal(opcode)) ..
      (nbytes >= 2 and (" to #" .. u16(data, 0)) or "") .. (op and (" (" .. op.name .. ")") or "")
  end
  return size
end

local function heuristic(tvb, pinfo, tree)
  local size = tvb:len()
  if size < 26 or size > 514 or size % 2 == 1 then return false end
  if tvb(0, 1):uint() ~= 1 or tvb(1, 1):uint() ~= 1 then return false end
  local nbytes = low(tvb(6, 2):uint(), 12)
  if 20 + nbytes + nbytes % 2 + 6 ~= size then return false end
  p_chudp.dissector(tvb, pinfo, tree)
  return true
end

function p_chudp.init()
  clients = {}
  servers = {}
  pending = {}
end

DissectorTable.get("udp.port"):add(42042, p_chudp)
p_chudp:register_heuristic("udp", heuristic)
"""


def render() -> str:
    return HEADER + "\n" + tables() + "\n" + BODY


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--check", action="store_true", help="exit 1 if the file is stale")
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = TARGET.read_text() if TARGET.exists() else ""
        if current != text:
            print(f"{TARGET} is stale: run python tools/gen_dissector.py", file=sys.stderr)
            return 1
        return 0
    TARGET.parent.mkdir(exist_ok=True)
    TARGET.write_text(text)
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
