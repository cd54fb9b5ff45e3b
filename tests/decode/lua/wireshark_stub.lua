-- The part of Wireshark's Lua API that dissectors/manip.lua uses, for a plain Lua interpreter (5.2 to
-- 5.4): a dissector runs here as in tshark, and every field it adds is printed, so the test can hold it
-- to manip-decode as it holds tshark (tests/decode/test_dissector.py).
--
--   lua5.4 tests/decode/lua/wireshark_stub.lua dissectors/manip.lua DATAGRAMS
--
-- DATAGRAMS has one UDP datagram a line: "source-port destination-port hex-payload".  The output is
-- one line per field, "abbrev<TAB>value" (a string value with \, tab and newline escaped), and a line
-- "--" after each packet.

local fields_out = {}

local function escape(s)
  return (s:gsub("\\", "\\\\"):gsub("\t", "\\t"):gsub("\n", "\\n"):gsub("\r", "\\r"))
end

local function shown(field, value)
  if field.kind == "string" or field.kind == "bytes" then return escape(tostring(value)) end
  if field.kind == "double" then return string.format("%.17g", value) end
  return string.format("%d", math.floor(value))
end

-- ---------------------------------------------------------------------------- bytes and ranges

local Tvb = {}
Tvb.__index = Tvb
local TvbRange = {}
TvbRange.__index = TvbRange

local function new_tvb(bytes) return setmetatable({bytes = bytes}, Tvb) end

function Tvb:len() return #self.bytes end
Tvb.__call = function(self, offset, length)
  length = length or (#self.bytes - offset)
  assert(offset >= 0 and offset + length <= #self.bytes, "range out of the buffer")
  return setmetatable({tvb = self, offset = offset, length = length}, TvbRange)
end

function TvbRange:uint()  -- big-endian, as Wireshark reads network data
  local v = 0
  for i = 1, self.length do v = v * 256 + self.tvb.bytes[self.offset + i] end
  return v
end
function TvbRange:len() return self.length end

ByteArray = {}
ByteArray.__index = ByteArray
function ByteArray.new() return setmetatable({bytes = {}, size = 0}, ByteArray) end
function ByteArray:set_size(n)
  for i = self.size + 1, n do self.bytes[i] = 0 end
  for i = n + 1, self.size do self.bytes[i] = nil end
  self.size = n
end
function ByteArray:set_index(i, v) assert(i < self.size) self.bytes[i + 1] = v end
function ByteArray:get_index(i) assert(i >= 0 and i < self.size, "index out of the array") return self.bytes[i + 1] end
function ByteArray:len() return self.size end
function ByteArray:tvb(_)
  local copy = {}
  for i = 1, self.size do copy[i] = self.bytes[i] end
  return new_tvb(copy)
end

-- ---------------------------------------------------------------------------- protocols and fields

local any = setmetatable({}, {__index = function(_, k) return k end})
base = any
expert = {group = any, severity = any}

local function field_maker(kind)
  return function(abbrev, name) return {abbrev = abbrev, name = name, kind = kind, is_field = true} end
end
ProtoField = {}
for _, kind in ipairs({"uint8", "uint16", "uint32", "int16", "double", "string", "bytes"}) do
  ProtoField[kind] = field_maker(kind)
end

ProtoExpert = {new = function(abbrev, text) return {abbrev = abbrev, text = text} end}

local heuristics = {}
local ports = {}

function Proto(name, description)
  local proto = {name = name, description = description, is_proto = true}
  function proto.register_heuristic(self, list, fn) heuristics[#heuristics + 1] = fn end
  return proto
end

DissectorTable = {get = function(_)
  return {add = function(_, port, proto) ports[port] = proto end}
end}

-- ---------------------------------------------------------------------------- the tree

local TreeItem = {}
TreeItem.__index = TreeItem

function TreeItem:add(what, a, b)
  if type(what) == "table" and what.is_field then
    local value = b
    if getmetatable(a) ~= TvbRange then value = a
    elseif value == nil then
      value = what.kind == "string" and "" or a:uint()
    end
    if what.abbrev:match("^chaos%.") or what.abbrev:match("^manip%.") then
      fields_out[#fields_out + 1] = what.abbrev .. "\t" .. shown(what, value)
    end
  end
  return setmetatable({}, TreeItem)
end
function TreeItem:append_text(_) return self end
function TreeItem:add_proto_expert_info(_, _) return self end

-- ---------------------------------------------------------------------------- the run

local script, datagrams = arg[1], arg[2]
dofile(script)

local function from_hex(text)
  local bytes = {}
  for pair in text:gmatch("%x%x") do bytes[#bytes + 1] = tonumber(pair, 16) end
  return bytes
end

for _, proto in pairs(ports) do if proto.init then proto.init() end end
for line in io.lines(datagrams) do
  local sport, dport, payload = line:match("^(%d+) (%d+) (%x*)$")
  assert(sport, "not a datagram line: " .. line)
  local pinfo = {src_port = tonumber(sport), dst_port = tonumber(dport), visited = false, cols = {}}
  local tvb, tree = new_tvb(from_hex(payload)), setmetatable({}, TreeItem)
  local proto = ports[pinfo.dst_port] or ports[pinfo.src_port]
  if proto then proto.dissector(tvb, pinfo, tree)
  else for _, fn in ipairs(heuristics) do if fn(tvb, pinfo, tree) then break end end end
  for _, f in ipairs(fields_out) do io.write(f, "\n") end
  io.write("--\n")
  fields_out = {}
end
