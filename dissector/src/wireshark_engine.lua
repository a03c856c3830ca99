
-- ---------------------------------------------------------------------------------------------
-- Engine (fixed part of the generated file): framing, reassembly, dissection, registration.
-- ---------------------------------------------------------------------------------------------

local ADDR_VS = { [0x01] = "host", [0x11] = "rack", [0x50] = "usb" }
for a = 0x21, 0x2A do ADDR_VS[a] = "bay" .. (a - 0x21) end

local F = {
  msgid = ProtoField.uint16("apt.msgid", "Message id", base.HEX),
  name = ProtoField.string("apt.name", "Message name"),
  data_len = ProtoField.uint16("apt.data_len", "Data length", base.DEC),
  param1 = ProtoField.uint8("apt.param1", "Param1", base.HEX),
  param2 = ProtoField.uint8("apt.param2", "Param2", base.HEX),
  dst = ProtoField.uint8("apt.dst", "Destination", base.HEX, ADDR_VS, 0x7f),
  data_flag = ProtoField.bool("apt.data_flag", "Data packet follows", 8, nil, 0x80),
  src = ProtoField.uint8("apt.src", "Source", base.HEX, ADDR_VS),
  chan = ProtoField.uint8("apt.chan", "Channel", base.DEC),
  sub = ProtoField.string("apt.sub", "Sub-message"),
  form = ProtoField.string("apt.form", "Form"),
  garbage = ProtoField.bytes("apt.garbage", "Bytes outside any frame"),
  pending = ProtoField.bytes("apt.pending", "Start of a frame continued in a later packet"),
  pair = ProtoField.framenum("apt.pair", "Request in", base.NONE, frametype.REQUEST),
  response_in = ProtoField.framenum("apt.response_in", "Response in", base.NONE, frametype.RESPONSE),
  latency_ms = ProtoField.double("apt.latency_ms", "Latency (ms)"),
}
local EF = {
  addr = ProtoField.string("ell.addr", "Address"),
  cmd = ProtoField.string("ell.cmd", "Command"),
  name = ProtoField.string("ell.name", "Command name"),
  data = ProtoField.string("ell.data", "Data"),
  garbage = ProtoField.bytes("ell.garbage", "Bytes outside any frame"),
  pair = ProtoField.framenum("ell.pair", "Request in", base.NONE, frametype.REQUEST),
  response_in = ProtoField.framenum("ell.response_in", "Response in", base.NONE, frametype.RESPONSE),
  latency_ms = ProtoField.double("ell.latency_ms", "Latency (ms)"),
}
local LF = {
  dir = ProtoField.uint8("aptscope.dir", "Direction", base.DEC,
    { [0] = "unknown", [1] = "host -> device", [2] = "device -> host" }),
  stream = ProtoField.uint8("aptscope.stream", "Stream", base.DEC),
}

local XA = {
  unknown_id = ProtoExpert.new("apt.expert.unknown_id", "Unknown message id",
    expert.group.UNDECODED, expert.severity.WARN),
  length = ProtoExpert.new("apt.expert.length_mismatch", "Data length fits no form of the message",
    expert.group.MALFORMED, expert.severity.WARN),
  truncated = ProtoExpert.new("apt.expert.truncated", "Frame truncated",
    expert.group.MALFORMED, expert.severity.ERROR),
  addr = ProtoExpert.new("apt.expert.unknown_address", "Unknown address",
    expert.group.PROTOCOL, expert.severity.WARN),
  sub = ProtoExpert.new("apt.expert.unknown_sub_id", "Unknown sub-message id",
    expert.group.UNDECODED, expert.severity.WARN),
  garbage = ProtoExpert.new("apt.expert.garbage", "Bytes that start no plausible APT header",
    expert.group.MALFORMED, expert.severity.WARN),
  pending = ProtoExpert.new("apt.expert.incomplete", "Frame continues in a later packet",
    expert.group.REASSEMBLE, expert.severity.NOTE),
}
local XE = {
  unknown_cmd = ProtoExpert.new("ell.expert.unknown_cmd", "Unknown command",
    expert.group.UNDECODED, expert.severity.WARN),
  bad_data = ProtoExpert.new("ell.expert.bad_data", "Data does not fit the command",
    expert.group.MALFORMED, expert.severity.WARN),
  garbage = ProtoExpert.new("ell.expert.garbage", "Bytes that start no Elliptec frame",
    expert.group.MALFORMED, expert.severity.WARN),
}

do
  local list = {}
  for _, f in pairs(F) do list[#list + 1] = f end
  for _, f in ipairs(APF) do list[#list + 1] = f end
  apt.fields = list
  local el = {}
  for _, f in pairs(EF) do el[#el + 1] = f end
  for _, f in ipairs(EPF) do el[#el + 1] = f end
  ell.fields = el
  link.fields = { LF.dir, LF.stream }
  local xa = {}
  for _, x in pairs(XA) do xa[#xa + 1] = x end
  apt.experts = xa
  local xe = {}
  for _, x in pairs(XE) do xe[#xe + 1] = x end
  ell.experts = xe
end

local f_ifid = Field.new("frame.interface_id")

-- ---- APT framing (the rules of aptscope's framer: plausible header, length within 255) ----

local KNOWN = { [0x01] = true, [0x11] = true, [0x50] = true }
for a = 0x21, 0x2A do KNOWN[a] = true end
local NEED, SKIP, ABSURD = -1, -2, -3

local function u16(s, i) return s:byte(i) + 256 * s:byte(i + 1) end

local function accepts_len(m, has_data, len)
  for _, fm in ipairs(m.forms) do
    if fm.k == HDR then
      if not has_data then return true end
    elseif fm.k == SUB then
      if has_data and m.subs and SUBLEN[m.subs] and SUBLEN[m.subs][len] then return true end
    elseif fm.k == OPEN then
      if has_data and len >= fm.min and len <= m.max and (len - fm.min) % fm.elem == 0 then
        return true
      end
    elseif has_data and fm.k == len then
      return true
    end
  end
  return false
end

-- What starts at s[i]: a frame length, NEED, SKIP or ABSURD.
local function apt_step(s, i)
  if #s - i + 1 < 6 then return NEED end
  local id = u16(s, i)
  local d = s:byte(i + 4)
  local has_data = d >= 0x80
  local dst = d % 0x80
  local src = s:byte(i + 5)
  local dst_ok, src_ok = KNOWN[dst], KNOWN[src]
  local zeros = dst == 0 and src == 0
  if not dst_ok and not src_ok and not zeros then return SKIP end
  local m = MSG[id]
  local len = has_data and u16(s, i + 2) or 0
  if len > (m and m.max or 255) then
    if m and dst_ok and src_ok then return ABSURD end
    return SKIP
  end
  local ok
  if dst_ok and src_ok then
    ok = true
  elseif zeros then
    ok = m ~= nil and m.d2h and accepts_len(m, has_data, len)
  else
    ok = m ~= nil and accepts_len(m, has_data, len)
  end
  if not ok then return SKIP end
  -- A data packet sent without the 0x80 flag, for a message that has no header-only form.
  if len == 0 and m and not accepts_len(m, false, 0) then
    local plen = u16(s, i + 2)
    if plen > 0 and plen <= m.max and accepts_len(m, true, plen) then return 6 + plen end
  end
  return 6 + len
end

-- ---- Elliptec framing: address, two letters, data, terminator ----

local function is_addr(c) return c:match("^[0-9A-Fa-f]$") ~= nil end

local function ell_step(s, i)
  local n = #s - i + 1
  if n < 1 then return NEED end
  if not is_addr(s:sub(i, i)) then return SKIP end
  if n < 3 then return NEED end
  if not s:sub(i + 1, i + 2):match("^%a%w$") then return SKIP end
  local c = CMD[s:sub(i + 1, i + 2)]
  if c and c.bin then
    local l = 3 + c.len
    if n < l then return NEED end
    local j = i + l
    if s:sub(j, j + 1) == "\r\n" then return l + 2 end
    local t = s:sub(j, j)
    if t == "\r" or t == "\n" then return l + 1 end
    return l
  end
  local lim = 3 + (c and c.len or 40) + 24
  local t = s:find("[\r\n]", i + 3)
  if t and t - i <= lim then
    if s:sub(t, t + 1) == "\r\n" then return t - i + 2 end
    return t - i + 1
  end
  if c and n > 3 + c.len then
    local nx = s:sub(i + 3 + c.len, i + 3 + c.len)
    if not nx:match("^[0-9A-Fa-f, ]$") then return 3 + c.len end
  end
  if n > lim then return SKIP end
  return NEED
end

-- ---- Per-capture state: streams, what each packet holds ----

local streams = {}   -- stream key -> bytes carried over
local last = {}      -- stream key -> packet number that left them
local prev = {}      -- stream key -> its latest packet number
local results = {}   -- packet number -> items
local detected = nil -- "apt" or "ell", decided by the first payload of the capture
local usb_dev = {}   -- USB device key -> { ftdi = true/false, mps = max packet size }
local waiting = {}   -- stream -> requests waiting for a reply, oldest first
local reframing = false -- a later pass frames again what a pass without tree framed

function link.init()
  streams, last, results, detected = {}, {}, {}, nil
  usb_dev = {}
  waiting = {}
  reframing = false
  prev = {}
end

local function detect(payload)
  if payload:match("^[0-9A-Fa-f][ ,]?%a%w") and not payload:find("[^\r\n\t\32-\126]") then
    return "ell"
  end
  return "apt"
end

-- Frame `payload` (a Lua string) on stream `key`; returns the packet's items.
local function frame_packet(key, payload, number)
  local proto = detected
  local carry = streams[key] or ""
  -- The stream goes on: what an earlier packet left pending was not the end of the capture.
  if #carry > 0 and last[key] and results[last[key]] then results[last[key]].continued = true end
  if prev[key] and results[prev[key]] then results[prev[key]].followed = true end
  prev[key] = number
  local buf = carry .. payload
  local step = proto == "ell" and ell_step or apt_step
  local items = {}
  local i, g = 1, nil
  local function flush_garbage(e)
    if g then
      items[#items + 1] = { k = "garbage", s = g, e = e }
      g = nil
    end
  end
  while i <= #buf do
    local r = step(buf, i)
    if r == NEED then
      -- Elliptec: a command without terminator that is exactly what is left.
      if proto == "ell" then
        local c = CMD[buf:sub(i + 1, i + 2)]
        if c and not c.bin and #buf - i + 1 == 3 + c.len then r = 3 + c.len end
      end
      if r == NEED then break end
    end
    if r == SKIP then
      g = g or i
      i = i + 1
    elseif r == ABSURD then
      g = g or i
      i = i + 6
    elseif #buf - i + 1 < r then
      break
    else
      flush_garbage(i - 1)
      items[#items + 1] = { k = proto, s = i, e = i + r - 1 }
      i = i + r
    end
  end
  flush_garbage(i - 1)
  streams[key] = buf:sub(i)
  local c = #carry
  local total = #buf - i + 1
  local out = { pending = math.min(total, #payload), pending_total = total }
  if total > 0 then
    out.tail = streams[key]
    last[key] = number
  end
  for _, it in ipairs(items) do
    if it.s > c then
      out[#out + 1] = { k = it.k, off = it.s - c - 1, len = it.e - it.s + 1 }
    else
      out[#out + 1] = { k = it.k, bytes = buf:sub(it.s, it.e) }
    end
  end
  return out
end

local function tohex(s)
  return (s:gsub(".", function(ch) return string.format("%02x", ch:byte()) end))
end

-- ---- APT dissection ----

local CHAN = { [1] = 1, [2] = 2, [4] = 3, [8] = 4 }
local ELEM_W = { u8 = 1, i8 = 1, u16 = 2, i16 = 2, u32 = 4, i32 = 4, f32 = 4 }

local function num(r, ty)
  if ty == "f32" then return r:le_float() end
  if ty:sub(1, 1) == "i" then return r:le_int() end
  return r:le_uint()
end

local function add_field(tree, t, f)
  local o, ty, cnt, pf, unit, scale, chan = f[1], f[2], f[3], f[4], f[5], f[6], f.chan
  local n = t:len()
  local ew = ELEM_W[ty]
  -- An open array (count 0): the whole elements left in the frame.
  if cnt == 0 and ew then cnt = math.floor((n - o) / ew) end
  local w = ew and ew * cnt or cnt
  if o + w > n then return end
  local r = t(o, w)
  if ty == "pad" then
    tree:add(r, string.format("reserved (%d bytes)", w))
  elseif ty == "str" then
    local s = r:raw()
    local z = s:find("\0", 1, true)
    if z then s = s:sub(1, z - 1) end
    tree:add(APF[pf], r, s)
  elseif ty == "bytes" then
    tree:add(APF[pf], r)
  else
    local parent = tree
    if cnt > 1 then
      parent = tree:add(r, string.format("array of %d %s", cnt, ty))
    end
    for k = 0, cnt - 1 do
      local er = t(o + k * ew, ew)
      local item = parent:add_le(APF[pf], er)
      local v = num(er, ty)
      if scale and unit then
        item:append_text(string.format(" = %g %s", v * scale, unit))
      elseif unit then
        item:append_text(" " .. unit)
      end
      local bits = f.bits
      if bits then
        for _, b in ipairs(bits) do item:add_le(APF[b], er) end
      end
      if chan then
        local ci = tree:add(F.chan, er, CHAN[v] or v)
        ci:set_generated()
      end
    end
  end
end

-- Request/reply pairing as aptscope does it (first pass, frames in order): a request waits for
-- the ids the table says answer it; a reply takes the oldest waiting request from its address
-- (else from any) on the same channel when both name one. `it` keeps the result.
local function pair(it, pinfo, m, ctx, src, dst, chan)
  local w = waiting[ctx.stream]
  if not w then
    w = {}
    waiting[ctx.stream] = w
  end
  local now = pinfo.abs_ts
  local keep = {}
  for _, p in ipairs(w) do
    if now - p.ts <= p.to / 1000 then keep[#keep + 1] = p end
  end
  w = keep
  waiting[ctx.stream] = w
  local from_host
  if ctx.dir == 1 or ctx.dir == 2 then from_host = ctx.dir == 1 else from_host = not m.d2h and src == 0x01 end
  if from_host then
    if next(m.rep) then
      w[#w + 1] = { pkt = pinfo.number, ts = now, rep = m.rep, to = m.to, device = dst, chan = chan,
        name = m.name, item = it }
    end
    return
  end
  local function ok(p) return p.rep[it.id] and (p.chan == nil or chan == nil or p.chan == chan) end
  local found
  for i, p in ipairs(w) do
    if ok(p) and p.device == src then found = i break end
  end
  if not found then
    for i, p in ipairs(w) do
      if ok(p) then found = i break end
    end
  end
  if not found then return end
  local p = table.remove(w, found)
  it.pair = p.pkt
  it.latency = (now - p.ts) * 1000
  p.item.response_in = p.item.response_in or pinfo.number
  -- The same message also completes other waiting requests to that device and channel, but a
  -- GET answers one REQ.
  local one_to_one = m.name:find("_GET_", 1, true) ~= nil
  local rest = {}
  for _, q in ipairs(w) do
    if q.rep[it.id] and q.device == p.device and q.chan == p.chan and not (one_to_one and q.name == p.name) then
      q.item.response_in = q.item.response_in or pinfo.number
    else
      rest[#rest + 1] = q
    end
  end
  waiting[ctx.stream] = rest
end

local function dissect_apt(t, pinfo, root, it, ctx)
  local n = t:len()
  local id = t(0, 2):le_uint()
  local m = MSG[id]
  local d = t(4, 1):uint()
  local has_data = d >= 0x80
  local dlen = has_data and t(2, 2):le_uint() or 0
  local src, dst = t(5, 1):uint(), d % 0x80
  local name = m and m.name or string.format("unknown id 0x%04x", id)
  local tree = root:add(apt, t(), "APT " .. name)
  tree:add_le(F.msgid, t(0, 2))
  if m then tree:add(F.name, t(0, 2), m.name):set_generated() end
  if has_data then
    tree:add_le(F.data_len, t(2, 2))
  else
    tree:add(F.param1, t(2, 1))
    tree:add(F.param2, t(3, 1))
  end
  local di = tree:add(F.dst, t(4, 1))
  tree:add(F.data_flag, t(4, 1))
  local si = tree:add(F.src, t(5, 1))
  if not (dst == 0 and src == 0) then
    if not KNOWN[dst] then di:add_proto_expert_info(XA.addr) end
    if not KNOWN[src] then si:add_proto_expert_info(XA.addr) end
  end
  -- A data packet without the 0x80 flag: the param bytes hold its length.
  if not has_data and n > 6 then
    has_data = true
    dlen = t(2, 2):le_uint()
  end
  if n < 6 + dlen then
    tree:add_proto_expert_info(XA.truncated,
      string.format("Frame truncated: %d of %d bytes", n, 6 + dlen))
  end
  if not m then
    tree:add_proto_expert_info(XA.unknown_id, string.format("Unknown message id 0x%04x", id))
    if n > 6 then tree:add(t(6, n - 6), "data") end
    return "0x" .. string.format("%04x", id)
  end
  local fields, form, sub
  for _, fm in ipairs(m.forms) do
    if fm.k == HDR and not has_data then
      form, fields = fm, fm.f
      if m.subs and fm.sid then
        sub = SUBS[m.subs] and SUBS[m.subs][t(2, 1):uint()]
        if not sub then tree:add_proto_expert_info(XA.sub) end
      end
      break
    elseif fm.k == SUB and has_data and dlen >= 2 and n >= 8 then
      form = fm
      local sid = t(6, 2):le_uint()
      sub = SUBS[m.subs] and SUBS[m.subs][sid]
      if not sub then
        tree:add_proto_expert_info(XA.sub, string.format("Unknown sub-message id %d", sid))
      else
        for _, sf in ipairs(sub.forms) do
          if sf.k == dlen then fields = sf.f end
        end
        if not fields then
          tree:add_proto_expert_info(XA.length,
            string.format("Data length %d fits no form of %s", dlen, sub.name))
        end
      end
      break
    elseif fm.k == dlen and has_data then
      form, fields = fm, fm.f
      break
    elseif fm.k == OPEN and has_data and accepts_len({ forms = { fm }, max = m.max }, true, dlen) then
      form, fields = fm, fm.f
      break
    end
  end
  if not form then
    tree:add_proto_expert_info(XA.length,
      string.format("Data length %d fits no form of %s", dlen, m.name))
  end
  if form and form.note ~= "" then tree:add(F.form, t(0, 2), form.note):set_generated() end
  if sub then tree:add(F.sub, t(0, 2), sub.name):set_generated() end
  for _, f in ipairs(fields or {}) do add_field(tree, t, f) end
  if not it.paired then
    local chan
    for _, f in ipairs(fields or {}) do
      if f.chan and f[1] < n then chan = t(f[1], 1):uint() end
    end
    it.id, it.paired = id, true
    pair(it, pinfo, m, ctx, src, dst, chan)
  end
  if it.pair then
    tree:add(F.pair, t(0, 2), it.pair):set_generated()
    tree:add(F.latency_ms, t(0, 2), it.latency):set_generated()
  end
  if it.response_in then tree:add(F.response_in, t(0, 2), it.response_in):set_generated() end
  local sname = ADDR_VS[src] or string.format("0x%02x", src)
  local dname = ADDR_VS[dst] or string.format("0x%02x", dst)
  tree:append_text(string.format(", %s -> %s", sname, dname))
  pinfo.cols.src = sname
  pinfo.cols.dst = dname
  return sub and (m.name .. "/" .. sub.name) or m.name
end

-- ---- Elliptec dissection ----

-- Elliptec pairing (first pass): a host command waits for its replies from the module it
-- addressed (from the new address for `ca`/`ga`); a BUSY status during a motion is interim.
local function ell_pair(it, pinfo, ctx, addr, code, c, status)
  local key = "ell" .. ctx.stream
  local now = pinfo.abs_ts
  local w = {}
  for _, p in ipairs(waiting[key] or {}) do
    if now - p.ts <= p.to / 1000 then w[#w + 1] = p end
  end
  waiting[key] = w
  if code:match("^%l") then
    if next(c.rep) and c.to > 0 then
      w[#w + 1] = { pkt = pinfo.number, ts = now, rep = c.rep, to = c.to, interim = c.interim,
        addr = (c.newaddr and it.newaddr) or addr, item = it }
    end
    return
  end
  for i, p in ipairs(w) do
    if p.addr == addr and p.rep[code] then
      it.pair = p.pkt
      it.latency = (now - p.ts) * 1000
      p.item.response_in = p.item.response_in or pinfo.number
      if not (code == "GS" and status == ELL_BUSY and p.interim) then table.remove(w, i) end
      return
    end
  end
end

local function dissect_ell(t, pinfo, root, it, ctx)
  local n = t:len()
  local s = t():raw()
  local tree = root:add(ell, t())
  local tn = #(s:match("[\r\n]*$"))
  local body = n - tn
  local a = 0
  tree:add(EF.addr, t(0, 1))
  if s:sub(2, 2) == " " or s:sub(2, 2) == "," then a = 1 end
  if body < 3 + a then return "?" end
  local code = s:sub(2 + a, 3 + a)
  tree:add(EF.cmd, t(1 + a, 2))
  local c = CMD[code]
  if not c then
    tree:add_proto_expert_info(XE.unknown_cmd, "Unknown command " .. code)
    tree:append_text(", " .. code)
    if body > 3 + a then tree:add(EF.data, t(3 + a, body - 3 - a)) end
    return code
  end
  -- Binary data (a current curve) may end in bytes equal to CR or LF: they are data, and only
  -- what follows its fixed length is the terminator, as ell_step frames it.
  if c.bin and n >= 3 + a + c.len then body = 3 + a + c.len end
  tree:add(EF.name, t(1 + a, 2), c.name):set_generated()
  tree:append_text(string.format(", %s %s %s", s:sub(1, 1), code, c.name))
  if code:match("^%l") then
    pinfo.cols.src, pinfo.cols.dst = "host", "module " .. s:sub(1, 1)
  else
    pinfo.cols.src, pinfo.cols.dst = "module " .. s:sub(1, 1), "host"
  end
  local o = 3 + a
  if (s:sub(o + 1, o + 1) == " " or s:sub(o + 1, o + 1) == ",") and c.len > 0 then o = o + 1 end
  for _, f in ipairs(c.f) do
    local w, kind, pf = f[1], f[2], f[3]
    if kind ~= "raw" then
      while s:sub(o + 1, o + 1) == "," or s:sub(o + 1, o + 1) == " " do o = o + 1 end
    end
    if o + w > body then
      tree:add_proto_expert_info(XE.bad_data, "Data shorter than the command's fields")
      break
    end
    local r = t(o, w)
    local txt = s:sub(o + 1, o + w)
    local p = EPF[pf]
    if kind == "raw" then
      tree:add(p, r)
    elseif kind == "dec" or kind == "addr" then
      tree:add(p, r, txt)
      if kind == "addr" then it.newaddr = txt:upper() end
    else
      local v = tonumber((txt:gsub("O", "0")), 16)
      if not v then
        tree:add_proto_expert_info(XE.bad_data, "Not hex: " .. txt)
      else
        if (kind == "position" or kind == "signed") and v >= 2 ^ (4 * w - 1) then
          v = v - 2 ^ (4 * w)
        end
        tree:add(p, r, v)
        if kind == "status" then it.status = v end
      end
    end
    o = o + w
  end
  if not it.paired then
    it.paired = true
    ell_pair(it, pinfo, ctx, s:sub(1, 1):upper(), code, c, it.status)
  end
  if it.pair then
    tree:add(EF.pair, t(0, 1), it.pair):set_generated()
    tree:add(EF.latency_ms, t(0, 1), it.latency):set_generated()
  end
  if it.response_in then tree:add(EF.response_in, t(0, 1), it.response_in):set_generated() end
  return s:sub(1, 1) .. code .. " " .. c.name
end

-- ---- The link layer: aptscope's pcapng (USER0) and pcap (USER1 + [direction, stream]) ----

local function dissect_link(tvb, pinfo, root, dir, stream, off)
  local len = tvb:len() - off
  if len <= 0 then return end
  if not pinfo.visited then
    local payload = tvb(off, len):raw()
    if detected == nil then detected = detect(payload) end
    local r = frame_packet(tostring(stream or "?") .. "/" .. dir, payload, pinfo.number)
    r.provisional = stream == nil
    results[pinfo.number] = r
  elseif stream ~= nil and results[pinfo.number] and results[pinfo.number].provisional then
    -- Framed without the interface id (a pass without protocol tree): frame again, in order,
    -- now that it is known, so interfaces do not mix; pairing is redone with the new frames.
    if not reframing then
      streams, last, prev, waiting, reframing = {}, {}, {}, {}, true
    end
    local old = results[pinfo.number]
    local r = frame_packet(stream .. "/" .. dir, tvb(off, len):raw(), pinfo.number)
    -- Whether the stream goes on is not known yet in this pass: a later packet in the same
    -- direction (of any interface) means pending bytes are not shown as a truncated frame.
    r.continued = old.followed
    results[pinfo.number] = r
  end
  local res = results[pinfo.number]
  if not res then return end
  local names = {}
  local protos = {}
  local ctx = { dir = dir, stream = stream or "?" }
  for idx, it in ipairs(res) do
    local t
    if it.bytes then
      t = ByteArray.new(tohex(it.bytes)):tvb(string.format("Reassembled frame %d", idx))
    else
      t = tvb(off + it.off, it.len):tvb()
    end
    if it.k == "garbage" then
      local fld = detected == "ell" and EF.garbage or F.garbage
      local item = root:add(fld, t())
      item:add_proto_expert_info(detected == "ell" and XE.garbage or XA.garbage)
    elseif it.k == "ell" then
      names[#names + 1] = dissect_ell(t, pinfo, root, it, ctx)
      protos.ELL = true
    else
      names[#names + 1] = dissect_apt(t, pinfo, root, it, ctx)
      protos.APT = true
    end
  end
  if res.pending > 0 and pinfo.visited and not res.continued and res.pending_total >= 3 then
    -- Second pass: nothing followed on this stream, so the pending bytes are a truncated frame.
    local t = ByteArray.new(tohex(res.tail)):tvb("Truncated frame")
    if detected == "ell" then
      names[#names + 1] = dissect_ell(t, pinfo, root, { paired = true }, ctx)
      protos.ELL = true
    elseif res.pending_total >= 6 then
      names[#names + 1] = dissect_apt(t, pinfo, root, { paired = true }, ctx)
      protos.APT = true
    end
  elseif res.pending > 0 then
    local item = root:add(detected == "ell" and EF.garbage or F.pending,
      tvb(tvb:len() - res.pending, res.pending))
    item:add_proto_expert_info(XA.pending, string.format(
      "%d bytes of a frame that continues in a later packet (truncated if none follows)",
      res.pending_total))
  end
  if protos.ELL then pinfo.cols.protocol = "ELL" elseif protos.APT then pinfo.cols.protocol = "APT" end
  local arrow = dir == 1 and "host->dev " or (dir == 2 and "dev->host " or "")
  if #names > 0 then
    pinfo.cols.info = arrow .. table.concat(names, ", ")
  elseif res.pending > 0 then
    pinfo.cols.info = arrow .. "[frame continues in a later packet]"
  end
end

local user0 = Proto("aptscope_ng", "aptscope serial capture (pcapng)")
function user0.dissector(tvb, pinfo, root)
  pinfo.cols.protocol = "aptscope"
  -- pcapng: direction in the packet flags (p2p_dir 0 sent = host -> device, 1 received).
  local dir = 0
  if pinfo.p2p_dir == 0 then dir = 1 elseif pinfo.p2p_dir == 1 then dir = 2 end
  -- The interface id, when this pass builds a protocol tree (tshark -2's first pass does not).
  local ifid = f_ifid()
  local stream = ifid and ifid.value
  local lt = root:add(link, tvb(0, 0))
  lt:add(LF.dir, tvb(0, 0), dir):set_generated()
  if stream then lt:add(LF.stream, tvb(0, 0), stream):set_generated() end
  dissect_link(tvb, pinfo, root, dir, stream, 0)
  return tvb:len()
end

local user1 = Proto("aptscope_pcap", "aptscope serial capture (pcap)")
function user1.dissector(tvb, pinfo, root)
  pinfo.cols.protocol = "aptscope"
  if tvb:len() < 2 then return 0 end
  local lt = root:add(link, tvb(0, 2))
  lt:add(LF.dir, tvb(0, 1))
  lt:add(LF.stream, tvb(1, 1))
  local dir, stream = tvb(0, 1):uint(), tvb(1, 1):uint()
  if dir == 1 then pinfo.p2p_dir = 0 elseif dir == 2 then pinfo.p2p_dir = 1 end
  dissect_link(tvb, pinfo, root, dir, stream, 2)
  return tvb:len()
end

-- ---- FTDI USB captures (usbmon, USBPcap): bulk transfers of the controller's FTDI chip ----


-- The first byte of an FTDI IN packet: modem status, bit 0 set, bits 2 and 3 clear.
local function ftdi_status_ok(b)
  return b % 16 < 4 and b % 4 ~= 0 and math.floor(b / 4) % 4 == 0
end

local function pieces_ok(s, mps)
  for i = 1, #s, mps do
    if #s - i + 1 < 2 or not ftdi_status_ok(s:byte(i)) then return false end
  end
  return true
end

local usbp = Proto("aptscope_usb", "aptscope FTDI serial over USB")

-- Dissect one bulk transfer of an FTDI device; `sure` when the device descriptor named it.
local function dissect_usb(tvb, pinfo, root, sure)
  -- Addresses, not field extractors: tshark -2 builds no tree in its first pass. Data of an OUT
  -- transfer goes host -> "bus.device.endpoint", of an IN transfer the other way.
  local src, dst = tostring(pinfo.src), tostring(pinfo.dst)
  local is_in = dst == "host"
  local bus, devno, ep = (is_in and src or dst):match("^(%d+)%.(%d+)%.(%d+)$")
  if not ep or ep == "0" or tvb:len() == 0 then return 0 end
  local key = bus .. ":" .. devno
  local dev = usb_dev[key]
  if not pinfo.visited then
    if not dev then
      dev = {}
      usb_dev[key] = dev
    end
    if dev.ftdi == nil then
      local s = tvb:raw()
      if sure then
        dev.ftdi = true
      elseif is_in then
        dev.ftdi = ftdi_status_ok(s:byte(1))
      else
        -- Host data before the first reply: believed when it starts a frame.
        local r = apt_step(s, 1)
        if not ((r > 0 and r <= #s) or detect(s) == "ell") then return 0 end
      end
    end
    if dev.ftdi == false then return 0 end
  end
  if not dev then return 0 end
  local t = tvb
  if is_in then
    local s = tvb:raw()
    if not dev.mps then
      dev.mps = (#s > 64 and not pieces_ok(s, 64) and pieces_ok(s, 512)) and 512 or 64
    end
    local parts = {}
    for i = 1, #s, dev.mps do parts[#parts + 1] = s:sub(i + 2, i + dev.mps - 1) end
    local data = table.concat(parts)
    if #data == 0 then return tvb:len() end -- status bytes only
    t = ByteArray.new(tohex(data)):tvb("FTDI data")
  end
  pinfo.p2p_dir = is_in and 1 or 0
  local lt = root:add(link, tvb(0, 0))
  lt:add(LF.dir, tvb(0, 0), is_in and 2 or 1):set_generated()
  lt:append_text(", USB device " .. key)
  dissect_link(t, pinfo, root, is_in and 2 or 1, key, 0)
  return tvb:len()
end

function usbp.dissector(tvb, pinfo, root)
  return dissect_usb(tvb, pinfo, root, true)
end

usbp:register_heuristic("usb.bulk", function(tvb, pinfo, root)
  return dissect_usb(tvb, pinfo, root, false) > 0
end)

do
  local products = DissectorTable.get("usb.product")
  -- Thorlabs APT controllers (0403:faf0) and the common FTDI chips Elliptec buses use.
  for _, pid in ipairs({ 0xfaf0, 0x6001, 0x6010, 0x6011, 0x6014, 0x6015 }) do
    products:add(0x04030000 + pid, usbp)
  end
end

do
  local enc = wtap_encaps or wtap
  local t = DissectorTable.get("wtap_encap")
  t:add(enc.USER0, user0)
  t:add(enc.USER1, user1)
end
