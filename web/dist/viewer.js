"use strict";
(() => {
  // node_modules/fzstd/esm/index.mjs
  var ab = ArrayBuffer;
  var u8 = Uint8Array;
  var u16 = Uint16Array;
  var i16 = Int16Array;
  var i32 = Int32Array;
  var slc = function(v, s, e) {
    if (u8.prototype.slice)
      return u8.prototype.slice.call(v, s, e);
    if (s == null || s < 0)
      s = 0;
    if (e == null || e > v.length)
      e = v.length;
    var n = new u8(e - s);
    n.set(v.subarray(s, e));
    return n;
  };
  var fill = function(v, n, s, e) {
    if (u8.prototype.fill)
      return u8.prototype.fill.call(v, n, s, e);
    if (s == null || s < 0)
      s = 0;
    if (e == null || e > v.length)
      e = v.length;
    for (; s < e; ++s)
      v[s] = n;
    return v;
  };
  var cpw = function(v, t, s, e) {
    if (u8.prototype.copyWithin)
      return u8.prototype.copyWithin.call(v, t, s, e);
    if (s == null || s < 0)
      s = 0;
    if (e == null || e > v.length)
      e = v.length;
    while (s < e) {
      v[t++] = v[s++];
    }
  };
  var ec = [
    "invalid zstd data",
    "window size too large (>2046MB)",
    "invalid block type",
    "FSE accuracy too high",
    "match distance too far back",
    "unexpected EOF"
  ];
  var err = function(ind, msg, nt) {
    var e = new Error(msg || ec[ind]);
    e.code = ind;
    if (Error.captureStackTrace)
      Error.captureStackTrace(e, err);
    if (!nt)
      throw e;
    return e;
  };
  var rb = function(d, b, n) {
    var i = 0, o = 0;
    for (; i < n; ++i)
      o |= d[b++] << (i << 3);
    return o;
  };
  var b4 = function(d, b) {
    return (d[b] | d[b + 1] << 8 | d[b + 2] << 16 | d[b + 3] << 24) >>> 0;
  };
  var rzfh = function(dat, w) {
    var n3 = dat[0] | dat[1] << 8 | dat[2] << 16;
    if (n3 == 3126568 && dat[3] == 253) {
      var flg = dat[4];
      var ss = flg >> 5 & 1, cc = flg >> 2 & 1, df = flg & 3, fcf = flg >> 6;
      if (flg & 8)
        err(0);
      var bt = 6 - ss;
      var db = df == 3 ? 4 : df;
      var di = rb(dat, bt, db);
      bt += db;
      var fsb = fcf ? 1 << fcf : ss;
      var fss = rb(dat, bt, fsb) + (fcf == 1 && 256);
      var ws = fss;
      if (!ss) {
        var wb = 1 << 10 + (dat[5] >> 3);
        ws = wb + (wb >> 3) * (dat[5] & 7);
      }
      if (ws > 2145386496)
        err(1);
      var buf = new u8((w == 1 ? fss || ws : w ? 0 : ws) + 12);
      buf[0] = 1, buf[4] = 4, buf[8] = 8;
      return {
        b: bt + fsb,
        y: 0,
        l: 0,
        d: di,
        w: w && w != 1 ? w : buf.subarray(12),
        e: ws,
        o: new i32(buf.buffer, 0, 3),
        u: fss,
        c: cc,
        m: Math.min(131072, ws)
      };
    } else if ((n3 >> 4 | dat[3] << 20) == 25481893) {
      return b4(dat, 4) + 8;
    }
    err(0);
  };
  var msb = function(val) {
    var bits = 0;
    for (; 1 << bits <= val; ++bits)
      ;
    return bits - 1;
  };
  var rfse = function(dat, bt, mal) {
    var tpos = (bt << 3) + 4;
    var al = (dat[bt] & 15) + 5;
    if (al > mal)
      err(3);
    var sz = 1 << al;
    var probs = sz, sym = -1, re = -1, i = -1, ht = sz;
    var buf = new ab(512 + (sz << 2));
    var freq = new i16(buf, 0, 256);
    var dstate = new u16(buf, 0, 256);
    var nstate = new u16(buf, 512, sz);
    var bb1 = 512 + (sz << 1);
    var syms = new u8(buf, bb1, sz);
    var nbits = new u8(buf, bb1 + sz);
    while (sym < 255 && probs > 0) {
      var bits = msb(probs + 1);
      var cbt = tpos >> 3;
      var msk = (1 << bits + 1) - 1;
      var val = (dat[cbt] | dat[cbt + 1] << 8 | dat[cbt + 2] << 16) >> (tpos & 7) & msk;
      var msk1fb = (1 << bits) - 1;
      var msv = msk - probs - 1;
      var sval = val & msk1fb;
      if (sval < msv)
        tpos += bits, val = sval;
      else {
        tpos += bits + 1;
        if (val > msk1fb)
          val -= msv;
      }
      freq[++sym] = --val;
      if (val == -1) {
        probs += val;
        syms[--ht] = sym;
      } else
        probs -= val;
      if (!val) {
        do {
          var rbt = tpos >> 3;
          re = (dat[rbt] | dat[rbt + 1] << 8) >> (tpos & 7) & 3;
          tpos += 2;
          sym += re;
        } while (re == 3);
      }
    }
    if (sym > 255 || probs)
      err(0);
    var sympos = 0;
    var sstep = (sz >> 1) + (sz >> 3) + 3;
    var smask = sz - 1;
    for (var s = 0; s <= sym; ++s) {
      var sf = freq[s];
      if (sf < 1) {
        dstate[s] = -sf;
        continue;
      }
      for (i = 0; i < sf; ++i) {
        syms[sympos] = s;
        do {
          sympos = sympos + sstep & smask;
        } while (sympos >= ht);
      }
    }
    if (sympos)
      err(0);
    for (i = 0; i < sz; ++i) {
      var ns = dstate[syms[i]]++;
      var nb = nbits[i] = al - msb(ns);
      nstate[i] = (ns << nb) - sz;
    }
    return [tpos + 7 >> 3, {
      b: al,
      s: syms,
      n: nbits,
      t: nstate
    }];
  };
  var rhu = function(dat, bt) {
    var i = 0, wc = -1;
    var buf = new u8(292), hb = dat[bt];
    var hw = buf.subarray(0, 256);
    var rc = buf.subarray(256, 268);
    var ri = new u16(buf.buffer, 268);
    if (hb < 128) {
      var _a = rfse(dat, bt + 1, 6), ebt = _a[0], fdt = _a[1];
      bt += hb;
      var epos = ebt << 3;
      var lb = dat[bt];
      if (!lb)
        err(0);
      var st1 = 0, st2 = 0, btr1 = fdt.b, btr2 = btr1;
      var fpos = (++bt << 3) - 8 + msb(lb);
      for (; ; ) {
        fpos -= btr1;
        if (fpos < epos)
          break;
        var cbt = fpos >> 3;
        st1 += (dat[cbt] | dat[cbt + 1] << 8) >> (fpos & 7) & (1 << btr1) - 1;
        hw[++wc] = fdt.s[st1];
        fpos -= btr2;
        if (fpos < epos)
          break;
        cbt = fpos >> 3;
        st2 += (dat[cbt] | dat[cbt + 1] << 8) >> (fpos & 7) & (1 << btr2) - 1;
        hw[++wc] = fdt.s[st2];
        btr1 = fdt.n[st1];
        st1 = fdt.t[st1];
        btr2 = fdt.n[st2];
        st2 = fdt.t[st2];
      }
      if (++wc > 255)
        err(0);
    } else {
      wc = hb - 127;
      for (; i < wc; i += 2) {
        var byte = dat[++bt];
        hw[i] = byte >> 4;
        hw[i + 1] = byte & 15;
      }
      ++bt;
    }
    var wes = 0;
    for (i = 0; i < wc; ++i) {
      var wt = hw[i];
      if (wt > 11)
        err(0);
      wes += wt && 1 << wt - 1;
    }
    var mb = msb(wes) + 1;
    var ts = 1 << mb;
    var rem = ts - wes;
    if (rem & rem - 1)
      err(0);
    hw[wc++] = msb(rem) + 1;
    for (i = 0; i < wc; ++i) {
      var wt = hw[i];
      ++rc[hw[i] = wt && mb + 1 - wt];
    }
    var hbuf = new u8(ts << 1);
    var syms = hbuf.subarray(0, ts), nb = hbuf.subarray(ts);
    ri[mb] = 0;
    for (i = mb; i > 0; --i) {
      var pv = ri[i];
      fill(nb, i, pv, ri[i - 1] = pv + rc[i] * (1 << mb - i));
    }
    if (ri[0] != ts)
      err(0);
    for (i = 0; i < wc; ++i) {
      var bits = hw[i];
      if (bits) {
        var code = ri[bits];
        fill(syms, i, code, ri[bits] = code + (1 << mb - bits));
      }
    }
    return [bt, {
      n: nb,
      b: mb,
      s: syms
    }];
  };
  var dllt = rfse(/* @__PURE__ */ new u8([
    81,
    16,
    99,
    140,
    49,
    198,
    24,
    99,
    12,
    33,
    196,
    24,
    99,
    102,
    102,
    134,
    70,
    146,
    4
  ]), 0, 6)[1];
  var dmlt = rfse(/* @__PURE__ */ new u8([
    33,
    20,
    196,
    24,
    99,
    140,
    33,
    132,
    16,
    66,
    8,
    33,
    132,
    16,
    66,
    8,
    33,
    68,
    68,
    68,
    68,
    68,
    68,
    68,
    68,
    36,
    9
  ]), 0, 6)[1];
  var doct = rfse(/* @__PURE__ */ new u8([
    32,
    132,
    16,
    66,
    102,
    70,
    68,
    68,
    68,
    68,
    36,
    73,
    2
  ]), 0, 5)[1];
  var b2bl = function(b, s) {
    var len = b.length, bl = new i32(len);
    for (var i = 0; i < len; ++i) {
      bl[i] = s;
      s += 1 << b[i];
    }
    return bl;
  };
  var llb = /* @__PURE__ */ new u8((/* @__PURE__ */ new i32([
    0,
    0,
    0,
    0,
    16843009,
    50528770,
    134678020,
    202050057,
    269422093
  ])).buffer, 0, 36);
  var llbl = /* @__PURE__ */ b2bl(llb, 0);
  var mlb = /* @__PURE__ */ new u8((/* @__PURE__ */ new i32([
    0,
    0,
    0,
    0,
    0,
    0,
    0,
    0,
    16843009,
    50528770,
    117769220,
    185207048,
    252579084,
    16
  ])).buffer, 0, 53);
  var mlbl = /* @__PURE__ */ b2bl(mlb, 3);
  var dhu = function(dat, out, hu) {
    var len = dat.length, ss = out.length, lb = dat[len - 1], msk = (1 << hu.b) - 1, eb = -hu.b;
    if (!lb)
      err(0);
    var st = 0, btr = hu.b, pos = (len << 3) - 8 + msb(lb) - btr, i = -1;
    for (; pos > eb && i < ss; ) {
      var cbt = pos >> 3;
      var val = (dat[cbt] | dat[cbt + 1] << 8 | dat[cbt + 2] << 16) >> (pos & 7);
      st = (st << btr | val) & msk;
      out[++i] = hu.s[st];
      pos -= btr = hu.n[st];
    }
    if (pos != eb || i + 1 != ss)
      err(0);
  };
  var dhu4 = function(dat, out, hu) {
    var bt = 6;
    var ss = out.length, sz1 = ss + 3 >> 2, sz2 = sz1 << 1, sz3 = sz1 + sz2;
    dhu(dat.subarray(bt, bt += dat[0] | dat[1] << 8), out.subarray(0, sz1), hu);
    dhu(dat.subarray(bt, bt += dat[2] | dat[3] << 8), out.subarray(sz1, sz2), hu);
    dhu(dat.subarray(bt, bt += dat[4] | dat[5] << 8), out.subarray(sz2, sz3), hu);
    dhu(dat.subarray(bt), out.subarray(sz3), hu);
  };
  var rzb = function(dat, st, out) {
    var _a;
    var bt = st.b;
    var b0 = dat[bt], btype = b0 >> 1 & 3;
    st.l = b0 & 1;
    var sz = b0 >> 3 | dat[bt + 1] << 5 | dat[bt + 2] << 13;
    var ebt = (bt += 3) + sz;
    if (btype == 1) {
      if (bt >= dat.length)
        return;
      st.b = bt + 1;
      if (out) {
        fill(out, dat[bt], st.y, st.y += sz);
        return out;
      }
      return fill(new u8(sz), dat[bt]);
    }
    if (ebt > dat.length)
      return;
    if (btype == 0) {
      st.b = ebt;
      if (out) {
        out.set(dat.subarray(bt, ebt), st.y);
        st.y += sz;
        return out;
      }
      return slc(dat, bt, ebt);
    }
    if (btype == 2) {
      var b3 = dat[bt], lbt = b3 & 3, sf = b3 >> 2 & 3;
      var lss = b3 >> 4, lcs = 0, s4 = 0;
      if (lbt < 2) {
        if (sf & 1)
          lss |= dat[++bt] << 4 | (sf & 2 && dat[++bt] << 12);
        else
          lss = b3 >> 3;
      } else {
        s4 = sf;
        if (sf < 2)
          lss |= (dat[++bt] & 63) << 4, lcs = dat[bt] >> 6 | dat[++bt] << 2;
        else if (sf == 2)
          lss |= dat[++bt] << 4 | (dat[++bt] & 3) << 12, lcs = dat[bt] >> 2 | dat[++bt] << 6;
        else
          lss |= dat[++bt] << 4 | (dat[++bt] & 63) << 12, lcs = dat[bt] >> 6 | dat[++bt] << 2 | dat[++bt] << 10;
      }
      ++bt;
      var buf = out ? out.subarray(st.y, st.y + st.m) : new u8(st.m);
      var spl = buf.length - lss;
      if (lbt == 0)
        buf.set(dat.subarray(bt, bt += lss), spl);
      else if (lbt == 1)
        fill(buf, dat[bt++], spl);
      else {
        var hu = st.h;
        if (lbt == 2) {
          var hud = rhu(dat, bt);
          lcs += bt - (bt = hud[0]);
          st.h = hu = hud[1];
        } else if (!hu)
          err(0);
        (s4 ? dhu4 : dhu)(dat.subarray(bt, bt += lcs), buf.subarray(spl), hu);
      }
      var ns = dat[bt++];
      if (ns) {
        if (ns == 255)
          ns = (dat[bt++] | dat[bt++] << 8) + 32512;
        else if (ns > 127)
          ns = ns - 128 << 8 | dat[bt++];
        var scm = dat[bt++];
        if (scm & 3)
          err(0);
        var dts = [dmlt, doct, dllt];
        for (var i = 2; i > -1; --i) {
          var md = scm >> (i << 1) + 2 & 3;
          if (md == 1) {
            var rbuf = new u8([0, 0, dat[bt++]]);
            dts[i] = {
              s: rbuf.subarray(2, 3),
              n: rbuf.subarray(0, 1),
              t: new u16(rbuf.buffer, 0, 1),
              b: 0
            };
          } else if (md == 2) {
            _a = rfse(dat, bt, 9 - (i & 1)), bt = _a[0], dts[i] = _a[1];
          } else if (md == 3) {
            if (!st.t)
              err(0);
            dts[i] = st.t[i];
          }
        }
        var _b = st.t = dts, mlt = _b[0], oct = _b[1], llt = _b[2];
        var lb = dat[ebt - 1];
        if (!lb)
          err(0);
        var spos = (ebt << 3) - 8 + msb(lb) - llt.b, cbt = spos >> 3, oubt = 0;
        var lst = (dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << llt.b) - 1;
        cbt = (spos -= oct.b) >> 3;
        var ost = (dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << oct.b) - 1;
        cbt = (spos -= mlt.b) >> 3;
        var mst = (dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << mlt.b) - 1;
        for (++ns; --ns; ) {
          var llc = llt.s[lst];
          var lbtr = llt.n[lst];
          var mlc = mlt.s[mst];
          var mbtr = mlt.n[mst];
          var ofc = oct.s[ost];
          var obtr = oct.n[ost];
          cbt = (spos -= ofc) >> 3;
          var ofp = 1 << ofc;
          var off = ofp + ((dat[cbt] | dat[cbt + 1] << 8 | dat[cbt + 2] << 16 | dat[cbt + 3] << 24) >>> (spos & 7) & ofp - 1);
          cbt = (spos -= mlb[mlc]) >> 3;
          var ml = mlbl[mlc] + ((dat[cbt] | dat[cbt + 1] << 8 | dat[cbt + 2] << 16) >> (spos & 7) & (1 << mlb[mlc]) - 1);
          cbt = (spos -= llb[llc]) >> 3;
          var ll = llbl[llc] + ((dat[cbt] | dat[cbt + 1] << 8 | dat[cbt + 2] << 16) >> (spos & 7) & (1 << llb[llc]) - 1);
          cbt = (spos -= lbtr) >> 3;
          lst = llt.t[lst] + ((dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << lbtr) - 1);
          cbt = (spos -= mbtr) >> 3;
          mst = mlt.t[mst] + ((dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << mbtr) - 1);
          cbt = (spos -= obtr) >> 3;
          ost = oct.t[ost] + ((dat[cbt] | dat[cbt + 1] << 8) >> (spos & 7) & (1 << obtr) - 1);
          if (off > 3) {
            st.o[2] = st.o[1];
            st.o[1] = st.o[0];
            st.o[0] = off -= 3;
          } else {
            var idx = off - (ll != 0);
            if (idx) {
              off = idx == 3 ? st.o[0] - 1 : st.o[idx];
              if (idx > 1)
                st.o[2] = st.o[1];
              st.o[1] = st.o[0];
              st.o[0] = off;
            } else
              off = st.o[0];
          }
          for (var i = 0; i < ll; ++i) {
            buf[oubt + i] = buf[spl + i];
          }
          oubt += ll, spl += ll;
          var stin = oubt - off;
          if (stin < 0) {
            var len = -stin;
            var bs = st.e + stin;
            if (len > ml)
              len = ml;
            for (var i = 0; i < len; ++i) {
              buf[oubt + i] = st.w[bs + i];
            }
            oubt += len, ml -= len, stin = 0;
          }
          for (var i = 0; i < ml; ++i) {
            buf[oubt + i] = buf[stin + i];
          }
          oubt += ml;
        }
        if (oubt != spl) {
          while (spl < buf.length) {
            buf[oubt++] = buf[spl++];
          }
        } else
          oubt = buf.length;
        if (out)
          st.y += oubt;
        else
          buf = slc(buf, 0, oubt);
      } else if (out) {
        st.y += lss;
        if (spl) {
          for (var i = 0; i < lss; ++i) {
            buf[i] = buf[spl + i];
          }
        }
      } else if (spl)
        buf = slc(buf, spl);
      st.b = ebt;
      return buf;
    }
    err(2);
  };
  var cct = function(bufs, ol) {
    if (bufs.length == 1)
      return bufs[0];
    var buf = new u8(ol);
    for (var i = 0, b = 0; i < bufs.length; ++i) {
      var chk = bufs[i];
      buf.set(chk, b);
      b += chk.length;
    }
    return buf;
  };
  function decompress(dat, buf) {
    var bufs = [], nb = +!buf;
    var bt = 0, ol = 0;
    for (; dat.length; ) {
      var st = rzfh(dat, nb || buf);
      if (typeof st == "object") {
        if (nb) {
          buf = null;
          if (st.w.length == st.u) {
            bufs.push(buf = st.w);
            ol += st.u;
          }
        } else {
          bufs.push(buf);
          st.e = 0;
        }
        for (; !st.l; ) {
          var blk = rzb(dat, st, buf);
          if (!blk)
            err(5);
          if (buf)
            st.e = st.y;
          else {
            bufs.push(blk);
            ol += blk.length;
            cpw(st.w, 0, blk.length);
            st.w.set(blk, st.w.length - blk.length);
          }
        }
        bt = st.b + st.c * 4;
      } else
        bt = st;
      dat = dat.subarray(bt);
    }
    return cct(bufs, ol);
  }

  // src/compact.ts
  var BUCKET_ENTRIES = 8;
  var CELL_POINTS = 7;
  var VALID_BIT = 2147483648;
  var TAG = 843273040;
  var FLAG_SNAPSHOT = 1;
  var HEADER_BYTES = 28;
  var TRANSFORM_WORDS = 12;
  var POINT_CHOICES = 2 * CELL_POINTS;
  var RANK_CHOICE = BUCKET_ENTRIES;
  var ENTRY_BYTES = 12;
  var POINT_BYTES = 4;
  var FIELDS = [
    [26, 5],
    [21, 5],
    [16, 5],
    [12, 4],
    [8, 4],
    [0, 8]
  ];
  var MAX_DECODED_BYTES = 256 << 20;
  var MAX_DECODE_LIMIT = 4 * 2 ** 30;
  var DeltaError = class extends Error {
  };
  function zstdContentSize(bytes) {
    if (bytes.length < 5) throw new DeltaError("corrupt compressed data: too short");
    const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    if (view.getUint32(0, true) !== 4247762216) throw new DeltaError("corrupt compressed data: bad zstd magic");
    const fhd = bytes[4];
    const fcsFlag = fhd >> 6;
    const single = fhd >> 5 & 1;
    const dictBytes = [0, 1, 2, 4][fhd & 3];
    const fcsBytes = fcsFlag === 0 ? single : [0, 2, 4, 8][fcsFlag];
    if (fcsBytes === 0) throw new DeltaError("compressed data does not record its decompressed size");
    const at = 5 + (single ? 0 : 1) + dictBytes;
    if (bytes.length < at + fcsBytes) throw new DeltaError("corrupt compressed data: truncated header");
    switch (fcsBytes) {
      case 1:
        return bytes[at];
      case 2:
        return view.getUint16(at, true) + 256;
      case 4:
        return view.getUint32(at, true);
      default: {
        const v = view.getBigUint64(at, true);
        return v > BigInt(Number.MAX_SAFE_INTEGER) ? Number.MAX_SAFE_INTEGER : Number(v);
      }
    }
  }
  function decompressLimited(bytes, limit) {
    const size = zstdContentSize(bytes);
    if (size > limit) {
      throw new DeltaError(`decompressed size ${size} bytes exceeds the limit of ${limit} bytes`);
    }
    let out;
    try {
      out = decompress(bytes, new Uint8Array(size));
    } catch (e) {
      throw new DeltaError(`corrupt compressed data: ${e}`);
    }
    if (out.length !== size) {
      throw new DeltaError(`corrupt compressed data: expanded to ${out.length} bytes, ${size} recorded`);
    }
    return out;
  }
  var VarReader = class {
    constructor(bytes) {
      this.bytes = bytes;
      this.at = 0;
    }
    left() {
      return this.bytes.length - this.at;
    }
    /// A varint as a number: exact up to 7 bytes (49 bits); longer ones (which no count or
    /// u32 delta can be) go through [`VarReader.varint`] for its checks and come back large.
    num(what) {
      const start = this.at;
      let v = 0;
      for (let k = 0; k < 7; k++) {
        if (this.at >= this.bytes.length) throw new DeltaError(`truncated ${what}`);
        const b = this.bytes[this.at++];
        v += (b & 127) * 2 ** (7 * k);
        if ((b & 128) === 0) return v;
      }
      this.at = start;
      return Number(this.varint(what));
    }
    varint(what) {
      let v = 0n;
      for (let shift = 0n; shift < 64n; shift += 7n) {
        if (this.at >= this.bytes.length) throw new DeltaError(`truncated ${what}`);
        const b = this.bytes[this.at++];
        const bits = BigInt(b & 127);
        if (shift === 63n && bits > 1n) throw new DeltaError(`bad varint in ${what}`);
        v |= bits << shift;
        if ((b & 128) === 0) return v;
      }
      throw new DeltaError(`bad varint in ${what}`);
    }
    /// A count of entries that each take at least one more byte.
    count(what) {
      const n = this.num(what);
      if (n > this.left()) throw new DeltaError(`truncated ${what}`);
      return n;
    }
    /// A zigzag delta against `prev.v`; the result must be a u32.
    delta(prev, what) {
      const z = this.num(what);
      const d = z % 2 === 0 ? z / 2 : -(z + 1) / 2;
      const v = prev.v + d;
      if (!(v >= 0 && v <= 4294967295)) throw new DeltaError(`bad varint in ${what}`);
      prev.v = v;
      return v;
    }
  };
  function unshuffle(planes) {
    const n = planes.length / 4;
    const words = new Uint32Array(n);
    for (let plane = 0; plane < 4; plane++) {
      const base = plane * n;
      const shift = 8 * plane;
      for (let i = 0; i < n; i++) words[i] |= planes[base + i] << shift;
    }
    return words;
  }
  function applyPointResidual(residual, reference) {
    let acc = VALID_BIT;
    for (const [shift, bits] of FIELDS) {
      const mask = (1 << bits) - 1;
      const z = residual >>> shift & mask;
      const d = (z >>> 1 ^ -(z & 1) & mask) >>> 0;
      acc = (acc | ((reference >>> shift) + d & mask) << shift) >>> 0;
    }
    return acc >>> 0;
  }
  function usedEntries(lo, hi, base) {
    let n = 0;
    while (n < BUCKET_ENTRIES && (lo[base + n] !== 0 || hi[base + n] !== 0)) n++;
    return n;
  }
  function usedPoints(points, base) {
    let n = 0;
    while (n < CELL_POINTS && points[base + n] !== 0) n++;
    return n;
  }
  function grown(a, words, max, what) {
    if (words <= a.length) return a;
    if (words > max) throw new DeltaError(`${what} out of range`);
    const b = new Uint32Array(Math.min(Math.max(words, 2 * a.length, 64), max));
    b.set(a);
    return b;
  }
  var OwnReferences = class {
    constructor(limit, bucketCounts) {
      this.limit = limit;
      this.bucketCounts = bucketCounts;
      this.isClientState = false;
      this.received = /* @__PURE__ */ new Map();
    }
    clear() {
      this.received.clear();
    }
    referenceOf(instance) {
      let r = this.received.get(instance);
      if (!r) {
        let buckets = Math.floor(this.limit / 4 / BUCKET_ENTRIES);
        if (this.bucketCounts) {
          if (instance >= this.bucketCounts.length) throw new DeltaError(`instance ${instance} out of range`);
          buckets = this.bucketCounts[instance];
        }
        const maxPoints = this.bucketCounts ? buckets * BUCKET_ENTRIES * CELL_POINTS : Math.floor(this.limit / 4);
        const empty = new Uint32Array(0);
        r = { keyLo: empty, keyHi: empty, slots: empty, points: empty, maxBucketWords: buckets * BUCKET_ENTRIES, maxPointWords: maxPoints };
        this.received.set(instance, r);
      }
      return r;
    }
  };
  function decodeCount(code, old, capacity, at, plane, what) {
    if (code > capacity) throw new DeltaError(`${what} ${code} exceeds ${capacity}`);
    const n = (code + old) % (capacity + 1);
    if (at + n > plane) throw new DeltaError(`byte planes hold ${plane} records, the index stream implies ${at + n}`);
    return n;
  }
  var EMPTY_CELL = new Uint32Array(CELL_POINTS);
  var CompactDecoder = class {
    /// Most decompressed bytes accepted per update (a client sets it from its instance table),
    /// and the instances' bucket counts when known (indices beyond them are refused; without
    /// them the reference arrays are bounded by the limit). With `store` (the client state),
    /// the references are the client's grids and every update is decoded into them.
    constructor(limit = MAX_DECODED_BYTES, bucketCounts = null, store = null) {
      this.limit = limit;
      this.transforms = /* @__PURE__ */ new Map();
      this.limit = Math.min(limit, MAX_DECODE_LIMIT);
      this.references = store ?? new OwnReferences(this.limit, bucketCounts);
    }
    clear() {
      this.transforms.clear();
      this.references.clear();
    }
    /// Decodes one update. After an error the state is undefined: the session must restart.
    decode(bytes) {
      const payload = decompressLimited(bytes, this.limit);
      if (payload.length < HEADER_BYTES) throw new DeltaError("truncated compact header");
      const view = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
      const word = (i) => view.getUint32(i, true);
      if (word(0) !== TAG) throw new DeltaError(`bad format tag ${word(0).toString(16)}`);
      const flags = word(4);
      if ((flags & ~FLAG_SNAPSHOT) !== 0) throw new DeltaError(`unknown flag bits ${flags}`);
      const frame = BigInt(word(8)) | BigInt(word(12)) << 32n;
      const indexLen = word(16);
      const rest = payload.subarray(HEADER_BYTES);
      if (indexLen > rest.length) throw new DeltaError("truncated index stream");
      const layout = parseIndex(rest.subarray(0, indexLen));
      const entries = word(20);
      const points = word(24);
      const s = split(layout, entries, points, rest.subarray(indexLen));
      const snapshot = (flags & FLAG_SNAPSHOT) !== 0;
      if (snapshot) this.clear();
      return this.assemble(layout, s, frame, snapshot);
    }
    assemble(layout, s, frame, snapshot) {
      const transforms = layout.transforms.map((instance, k) => {
        const old = this.transforms.get(instance) ?? new Uint32Array(TRANSFORM_WORDS);
        const words = new Uint32Array(TRANSFORM_WORDS);
        for (let i = 0; i < TRANSFORM_WORDS; i++) words[i] = (s.transforms[k * TRANSFORM_WORDS + i] ^ old[i]) >>> 0;
        this.transforms.set(instance, words);
        return [instance, new Float32Array(words.buffer.slice(0))];
      });
      let entryCount = 0;
      let cellCount = 0;
      let entry = 0;
      let point = 0;
      const instances = [];
      for (const { instance, buckets: bucketIds, cells: slotIds } of layout.instances) {
        const r = this.references.referenceOf(instance);
        const nb = bucketIds.length;
        const lo = new Uint32Array(nb * BUCKET_ENTRIES);
        const hi = new Uint32Array(nb * BUCKET_ENTRIES);
        const slots = new Uint32Array(nb * BUCKET_ENTRIES);
        for (let k = 0; k < nb; k++) {
          const b = bucketIds[k];
          const base = b * BUCKET_ENTRIES;
          const end = base + BUCKET_ENTRIES;
          r.keyLo = grown(r.keyLo, end, r.maxBucketWords, `bucket ${b}`);
          r.keyHi = grown(r.keyHi, end, r.maxBucketWords, `bucket ${b}`);
          r.slots = grown(r.slots, end, r.maxBucketWords, `bucket ${b}`);
          const code = s.entryCounts[entryCount++];
          const n = decodeCount(code, usedEntries(r.keyLo, r.keyHi, base), BUCKET_ENTRIES, entry, s.entryChoices.length, "bucket entry count");
          const out = k * BUCKET_ENTRIES;
          for (let i = 0; i < n; i++) {
            const c = s.entryChoices[entry];
            let tLo = s.keyLo[entry];
            let tHi = s.keyHi[entry];
            const sr = s.slots[entry];
            entry++;
            let slot;
            if (c === RANK_CHOICE) {
              if (sr >= slotIds.length) throw new DeltaError("bad reference choice for a bucket entry");
              slot = slotIds[sr];
            } else if (c < RANK_CHOICE) {
              const o = base + (i + c) % BUCKET_ENTRIES;
              const rLo2 = r.keyLo[o];
              const rHi2 = r.keyHi[o];
              if (rLo2 !== 0 || rHi2 !== 0) {
                const mLo = rLo2 === 0 ? 4294967295 : rLo2 - 1;
                const mHi = rLo2 === 0 ? rHi2 - 1 : rHi2;
                tLo = (tLo ^ mLo ^ b) >>> 0;
                tHi = (tHi ^ mHi) >>> 0;
              }
              slot = (sr ^ r.slots[o]) >>> 0;
            } else {
              throw new DeltaError("bad reference choice for a bucket entry");
            }
            const xLo = (tLo ^ b) >>> 0;
            if (xLo === 4294967295 && tHi === 4294967295) throw new DeltaError("bad bucket key");
            lo[out + i] = xLo === 4294967295 ? 0 : xLo + 1;
            hi[out + i] = xLo === 4294967295 ? tHi + 1 : tHi;
            slots[out + i] = slot;
          }
          const rLo = r.keyLo;
          const rHi = r.keyHi;
          const rSlots = r.slots;
          for (let i = 0; i < BUCKET_ENTRIES; i++) {
            rLo[base + i] = lo[out + i];
            rHi[base + i] = hi[out + i];
            rSlots[base + i] = slots[out + i];
          }
        }
        const nc = slotIds.length;
        const pts = new Uint32Array(nc * CELL_POINTS);
        for (let k = 0; k < nc; k++) {
          const slot = slotIds[k];
          const base = slot * CELL_POINTS;
          r.points = grown(r.points, base + CELL_POINTS, r.maxPointWords, `cell slot ${slot}`);
          const old = r.points;
          const code = s.cellLengths[cellCount++];
          const n = decodeCount(code, usedPoints(old, base), CELL_POINTS, point, s.pointChoices.length, "cell length");
          const out = k * CELL_POINTS;
          for (let i = 0; i < n; i++) {
            const c = s.pointChoices[point];
            const residual = s.points[point];
            point++;
            if (c >= POINT_CHOICES) throw new DeltaError("bad reference choice for a point");
            if ((residual & VALID_BIT) !== 0) throw new DeltaError("bad point residual");
            const reference = c < CELL_POINTS ? old[base + (i + c) % CELL_POINTS] : k > 0 ? pts[out - CELL_POINTS + c - CELL_POINTS] : EMPTY_CELL[0];
            pts[out + i] = applyPointResidual(residual, reference);
          }
          for (let i = 0; i < CELL_POINTS; i++) old[base + i] = pts[out + i];
        }
        instances.push({
          instance,
          bucketIds: Uint32Array.from(bucketIds),
          keyLo: lo,
          keyHi: hi,
          slots,
          cellSlots: Uint32Array.from(slotIds),
          points: pts
        });
      }
      if (entry !== s.entryChoices.length || point !== s.pointChoices.length) {
        throw new DeltaError(`${s.entryChoices.length - entry + s.pointChoices.length - point} trailing records`);
      }
      return { frame, snapshot, transforms, instances, inPlace: this.references.isClientState };
    }
  };
  function parseIndex(bytes) {
    const r = new VarReader(bytes);
    const transforms = [];
    let n = r.count("transform count");
    const prevT = { v: -1 };
    for (let i = 0; i < n; i++) transforms.push(r.delta(prevT, "transform instance"));
    n = r.count("instance count");
    const instances = [];
    const prevI = { v: -1 };
    for (let k = 0; k < n; k++) {
      const instance = r.delta(prevI, "instance");
      const nb = r.count("bucket count");
      const nc = r.count("cell count");
      const buckets = [];
      const prevB = { v: -1 };
      for (let i = 0; i < nb; i++) buckets.push(r.delta(prevB, "bucket index"));
      const cells = [];
      const prevC = { v: -1 };
      for (let i = 0; i < nc; i++) cells.push(r.delta(prevC, "cell slot"));
      instances.push({ instance, buckets, cells });
    }
    if (r.left() !== 0) throw new DeltaError(`${r.left()} trailing bytes after the index stream`);
    return { transforms, instances };
  }
  function split(layout, entries, points, bytes) {
    let nb = 0;
    let nc = 0;
    for (const i of layout.instances) {
      nb += i.buckets.length;
      nc += i.cells.length;
    }
    const transformBytes = layout.transforms.length * TRANSFORM_WORDS * 4;
    const expected = nb + nc + entries * (1 + ENTRY_BYTES) + points * (1 + POINT_BYTES) + transformBytes;
    if (bytes.length !== expected) {
      throw new DeltaError(`byte planes hold ${bytes.length} bytes, the index stream implies ${expected}`);
    }
    let at = 0;
    const take = (n) => bytes.subarray(at, at += n);
    const entryCounts = take(nb);
    const cellLengths = take(nc);
    const entryChoices = take(entries);
    const pointChoices = take(points);
    const keyPlanes = take(entries * 8);
    const slots = unshuffle(take(entries * 4));
    const pts = unshuffle(take(points * 4));
    const transforms = unshuffle(take(transformBytes));
    const keyLo = new Uint32Array(entries);
    const keyHi = new Uint32Array(entries);
    for (let p = 0; p < 4; p++) {
      for (let i = 0; i < entries; i++) {
        keyLo[i] |= keyPlanes[p * entries + i] << 8 * p;
        keyHi[i] |= keyPlanes[(p + 4) * entries + i] << 8 * p;
      }
    }
    return { entryCounts, cellLengths, entryChoices, pointChoices, keyLo, keyHi, slots, points: pts, transforms };
  }

  // src/state.ts
  var MAX_DIM = 1 << 21;
  var ApplyError = class extends Error {
  };
  var Grid = class {
    constructor(entry) {
      this.entry = entry;
      /// Cell slots in use (at most the length `points` covers).
      this.slotCount = 0;
      this.maxBucketWords = entry.bucketCount * BUCKET_ENTRIES;
      this.maxPointWords = this.maxBucketWords * CELL_POINTS;
      this.keyLo = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.keyHi = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.slots = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.points = new Uint32Array(0);
    }
    /// Empties the grid (a snapshot follows), keeping its memory.
    clear() {
      this.keyLo.fill(0);
      this.keyHi.fill(0);
      this.slots.fill(0);
      this.points.fill(0);
      this.slotCount = 0;
    }
    /// Most cell slots the layout allows.
    maxCells() {
      return this.entry.bucketCount * BUCKET_ENTRIES;
    }
    ensureSlot(slot) {
      if (slot < this.slotCount) return;
      this.slotCount = slot + 1;
      if (this.points.length < this.slotCount * CELL_POINTS) {
        const cells = Math.min(Math.max(this.slotCount, 2 * Math.floor(this.points.length / CELL_POINTS)), Math.max(this.slotCount, this.maxCells()));
        const grown2 = new Uint32Array(cells * CELL_POINTS);
        grown2.set(this.points);
        this.points = grown2;
      }
    }
    /// Whether cell id `hi · 2^32 + lo` lies in the grid (psao-points' `coord_of_id`): in
    /// doubles below 2^53 (exact), else in BigInt.
    idIsValid(hi, lo) {
      const [dx, dy, dz] = this.entry.dims;
      const slice = dx * dy * 31;
      const row = dx * 17;
      if (hi < 1 << 21 && slice < 2 ** 52) {
        const id = hi * 2 ** 32 + lo;
        let z = Math.floor(id / slice);
        if (z * slice > id) z--;
        const rem = id - z * slice;
        let y = Math.floor(rem / row);
        if (y * row > rem) y--;
        const x = rem - y * row;
        return x < dx && y < dy && z < dz;
      }
      return this.idIsValidBig(BigInt(hi) << 32n | BigInt(lo));
    }
    idIsValidBig(id) {
      const [dx, dy, dz] = this.entry.dims.map(BigInt);
      const slice = dx * dy * 31n;
      const row = dx * 17n;
      const z = id / slice;
      const rem = id % slice;
      return rem % row < dx && rem / row < dy && z < dz;
    }
  };
  function usable(e) {
    const ids = 31n * e.dims.reduce((a, d) => a * BigInt(d), 1n);
    return e.origin.every(Number.isFinite) && Number.isFinite(e.cellSize) && e.cellSize > 0 && Number.isFinite(e.layoutPoissonRadius) && e.layoutPoissonRadius >= 0 && e.dims.every((d) => d >= 1 && d <= MAX_DIM) && ids < 0xffffffffffffffffn && e.bucketCount > 0 && (e.bucketCount & e.bucketCount - 1) === 0;
  }
  var ClientState = class {
    constructor(table) {
      this.isClientState = true;
      this.lastFrame = null;
      this.grids = table.map((e) => usable(e) ? new Grid(e) : null);
      this.transforms = table.map(() => null);
    }
    /// Instance `instance`'s grid as the decoder's reference.
    referenceOf(instance) {
      if (instance >= this.grids.length) throw new DeltaError(`instance ${instance} out of range (${this.grids.length} instances)`);
      const g = this.grids[instance];
      if (!g) throw new DeltaError(`instance ${instance} has no grid`);
      return g;
    }
    /// Empties every grid and forgets the transforms (a snapshot follows).
    clear() {
      for (const g of this.grids) g?.clear();
      this.transforms.fill(null);
    }
    /// Applies a decoded update after checking all of it. An update decoded elsewhere changes
    /// nothing on an error; one decoded into this state (`inPlace`) is already in the grids,
    /// so after an error the state is undefined and the session must restart.
    apply(u) {
      this.validate(u);
      if (u.snapshot && !u.inPlace) this.clear();
      for (const [instance, t] of u.transforms) this.transforms[instance] = t;
      for (const d of u.instances) {
        const g = this.grids[d.instance];
        if (u.inPlace) {
          for (let i = 0; i < d.keyLo.length; i++) {
            if (d.keyLo[i] !== 0 || d.keyHi[i] !== 0) g.ensureSlot(d.slots[i]);
          }
          for (let k = 0; k < d.cellSlots.length; k++) g.ensureSlot(d.cellSlots[k]);
          continue;
        }
        for (let k = 0; k < d.bucketIds.length; k++) {
          const base = d.bucketIds[k] * BUCKET_ENTRIES;
          const src = k * BUCKET_ENTRIES;
          for (let i = 0; i < BUCKET_ENTRIES; i++) {
            const lo = d.keyLo[src + i];
            const hi = d.keyHi[src + i];
            g.keyLo[base + i] = lo;
            g.keyHi[base + i] = hi;
            g.slots[base + i] = d.slots[src + i];
            if (lo !== 0 || hi !== 0) g.ensureSlot(d.slots[src + i]);
          }
        }
        for (let k = 0; k < d.cellSlots.length; k++) {
          const slot = d.cellSlots[k];
          g.ensureSlot(slot);
          g.points.set(d.points.subarray(k * CELL_POINTS, (k + 1) * CELL_POINTS), slot * CELL_POINTS);
        }
      }
      this.lastFrame = u.frame;
    }
    validate(u) {
      const count = this.grids.length;
      const inRange = (i) => {
        if (i >= count) throw new ApplyError(`instance ${i} out of range (${count} instances)`);
      };
      for (const [i, t] of u.transforms) {
        inRange(i);
        if (!t.every(Number.isFinite)) throw new ApplyError(`instance ${i}: transform is not finite`);
      }
      for (const d of u.instances) {
        inRange(d.instance);
        const g = this.grids[d.instance];
        if (!g) throw new ApplyError(`instance ${d.instance} has no grid`);
        const max = g.maxCells();
        const mask = g.entry.bucketCount - 1;
        for (let k = 0; k < d.bucketIds.length; k++) {
          const b = d.bucketIds[k];
          if (b >= g.entry.bucketCount) throw new ApplyError(`instance ${d.instance}: bucket ${b} out of range`);
          for (let i = k * BUCKET_ENTRIES; i < (k + 1) * BUCKET_ENTRIES; i++) {
            const lo = d.keyLo[i];
            const hi = d.keyHi[i];
            if (lo === 0 && hi === 0) continue;
            if (d.slots[i] >= max) throw new ApplyError(`instance ${d.instance}: cell slot ${d.slots[i]} out of range`);
            const idLo = lo === 0 ? 4294967295 : lo - 1;
            const idHi = lo === 0 ? hi - 1 : hi;
            if (!g.idIsValid(idHi, idLo) || (idLo & mask) >>> 0 !== b) {
              throw new ApplyError(`instance ${d.instance}: bucket ${b} has an invalid cell key`);
            }
          }
        }
        for (const slot of d.cellSlots) {
          if (slot >= max) throw new ApplyError(`instance ${d.instance}: cell slot ${slot} out of range`);
        }
      }
    }
    /// The state hash of psao-client (`state_hash_of`): every grid's compacted buckets and
    /// used cells folded into one 64-bit word.
    stateHash() {
      const h = new Hasher(608135816, 2242054355);
      for (const g of this.grids) {
        if (!g) {
          h.word(NO_GRID_HI, NO_GRID_LO);
          continue;
        }
        h.word(0, g.entry.bucketCount);
        for (let b = 0; b < g.entry.bucketCount; b++) {
          const base = b * BUCKET_ENTRIES;
          let used = 0;
          for (let i = 0; i < BUCKET_ENTRIES; i++) {
            const lo = g.keyLo[base + i];
            const hi = g.keyHi[base + i];
            if (lo === 0 && hi === 0) continue;
            h.word(hi, lo);
            h.word(0, g.slots[base + i]);
            used++;
          }
          for (; used < BUCKET_ENTRIES; used++) {
            h.word(0, 0);
            h.word(0, 0);
          }
        }
        let usedCells = 0;
        for (let s = g.slotCount - 1; s >= 0; s--) {
          if (validPoints(g.points, s) > 0) {
            usedCells = s + 1;
            break;
          }
        }
        h.word(0, usedCells);
        const compact = new Uint32Array(CELL_POINTS + 1);
        for (let s = 0; s < usedCells; s++) {
          compact.fill(0);
          let n = 0;
          for (let i = 0; i < CELL_POINTS; i++) {
            const p = g.points[s * CELL_POINTS + i];
            if ((p & VALID_BIT) !== 0) compact[n++] = p;
          }
          for (let i = 0; i < CELL_POINTS; i += 2) {
            h.word(compact[i + 1], compact[i]);
          }
        }
      }
      h.word(0, this.grids.length);
      return h.finish();
    }
  };
  function validPoints(points, slot) {
    let n = 0;
    for (let i = 0; i < CELL_POINTS; i++) if ((points[slot * CELL_POINTS + i] & VALID_BIT) !== 0) n++;
    return n;
  }
  var NO_GRID_HI = 1852792679;
  var NO_GRID_LO = 1919509537;
  var K_HI = 1367130551;
  var K_LO = 656542357;
  var K_LO0 = K_LO & 65535;
  var K_LO1 = K_LO >>> 16;
  var M64 = 0xffffffffffffffffn;
  var Hasher = class {
    constructor(hi, lo) {
      this.hi = hi;
      this.lo = lo;
    }
    word(wHi, wLo) {
      const xHi = (this.hi << 5 | this.lo >>> 27) ^ wHi;
      const xLo = (this.lo << 5 | this.hi >>> 27) ^ wLo;
      const a0 = xLo & 65535;
      const a1 = xLo >>> 16;
      const p00 = a0 * K_LO0;
      const p01 = a0 * K_LO1;
      const p10 = a1 * K_LO0;
      const mid = (p00 >>> 16) + (p01 & 65535) + (p10 & 65535);
      const carry = a1 * K_LO1 + (p01 >>> 16) + (p10 >>> 16) + (mid >>> 16);
      this.lo = Math.imul(xLo, K_LO) >>> 0;
      this.hi = carry + Math.imul(xHi, K_LO) + Math.imul(xLo, K_HI) >>> 0;
    }
    finish() {
      let z = BigInt(this.hi) << 32n | BigInt(this.lo);
      z = (z ^ z >> 30n) * 0xbf58476d1ce4e5b9n & M64;
      z = (z ^ z >> 27n) * 0x94d049bb133111ebn & M64;
      return z ^ z >> 31n;
    }
  };

  // src/wire.ts
  var MAGIC = [80, 83, 87, 49];
  var HEADER_LEN = 12;
  var PROTOCOL_VERSION = 2;
  var MAX_SERVER_FRAME = 256 << 20;
  var CAP_CODEC_COMPACT = 2;
  var CAP_STATE_HASH = 4;
  var CAP_STATUS = 16;
  var ERROR_CODES = ["Version", "Token", "Frame", "Protocol", "Update", "Server"];
  var WireError = class extends Error {
  };
  var CRC_TABLE = (() => {
    const t = new Uint32Array(256);
    for (let n = 0; n < 256; n++) {
      let c = n;
      for (let k = 0; k < 8; k++) c = c & 1 ? 3988292384 ^ c >>> 1 : c >>> 1;
      t[n] = c >>> 0;
    }
    return t;
  })();
  function crc32(bytes) {
    let c = 4294967295;
    for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 255] ^ c >>> 8;
    return (c ^ 4294967295) >>> 0;
  }
  var Reader = class {
    constructor(bytes) {
      this.bytes = bytes;
      this.at = 0;
      this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    }
    need(n, what) {
      if (this.at + n > this.bytes.length) throw new WireError(`truncated ${what}`);
    }
    done() {
      return this.at === this.bytes.length;
    }
    rest() {
      return this.bytes.length - this.at;
    }
    varint(what, maxBits) {
      let v = 0n;
      for (let shift = 0n; ; shift += 7n) {
        this.need(1, what);
        const b = this.bytes[this.at++];
        v |= BigInt(b & 127) << shift;
        if ((b & 128) === 0) break;
        if (shift + 7n >= BigInt(maxBits + 7)) throw new WireError(`varint too long in ${what}`);
      }
      if (v >> BigInt(maxBits) !== 0n) throw new WireError(`${what} out of range`);
      return v;
    }
    u16(what) {
      return Number(this.varint(what, 16));
    }
    u32(what) {
      return Number(this.varint(what, 32));
    }
    /// A u64 that must fit a JS number exactly (frame counters).
    u64n(what) {
      const v = this.varint(what, 64);
      if (v > BigInt(Number.MAX_SAFE_INTEGER)) throw new WireError(`${what} too large`);
      return Number(v);
    }
    u64(what) {
      return this.varint(what, 64);
    }
    bool(what) {
      this.need(1, what);
      const b = this.bytes[this.at++];
      if (b > 1) throw new WireError(`bad bool in ${what}`);
      return b === 1;
    }
    f32(what) {
      this.need(4, what);
      const v = this.view.getFloat32(this.at, true);
      this.at += 4;
      return v;
    }
    f64(what) {
      this.need(8, what);
      const v = this.view.getFloat64(this.at, true);
      this.at += 8;
      return v;
    }
    bytesField(what) {
      const n = this.u32(what);
      this.need(n, what);
      const out = this.bytes.subarray(this.at, this.at + n);
      this.at += n;
      return out;
    }
    string(what) {
      try {
        return new TextDecoder("utf-8", { fatal: true }).decode(this.bytesField(what));
      } catch (e) {
        if (e instanceof WireError) throw e;
        throw new WireError(`${what} is not UTF-8`);
      }
    }
    option(what, read) {
      return this.bool(what) ? read() : null;
    }
    vec3(what) {
      return [this.f32(what), this.f32(what), this.f32(what)];
    }
  };
  var Writer = class {
    constructor() {
      this.out = [];
    }
    varint(v) {
      let x = BigInt(v);
      do {
        let b = Number(x & 0x7fn);
        x >>= 7n;
        if (x !== 0n) b |= 128;
        this.out.push(b);
      } while (x !== 0n);
    }
    bool(b) {
      this.out.push(b ? 1 : 0);
    }
    f32(v) {
      const b = new Uint8Array(4);
      new DataView(b.buffer).setFloat32(0, v, true);
      this.out.push(...b);
    }
    string(s) {
      const b = new TextEncoder().encode(s);
      this.varint(b.length);
      this.out.push(...b);
    }
  };
  function finite(what, values) {
    if (!values.every(Number.isFinite)) throw new WireError(`${what} is not finite`);
  }
  function readInstance(r) {
    const e = {
      origin: r.vec3("origin"),
      cellSize: r.f32("cell size"),
      dims: [r.u32("dims"), r.u32("dims"), r.u32("dims")],
      layoutPoissonRadius: r.f32("layout poisson radius"),
      bucketCount: r.u32("bucket count"),
      poissonRadius: r.f32("poisson radius"),
      pointCount: r.u32("point count")
    };
    finite("instance entry", [...e.origin, e.cellSize, e.layoutPoissonRadius, e.poissonRadius]);
    return e;
  }
  function readDelta(r) {
    return {
      frame: r.u64n("frame"),
      sceneTime: r.f64("scene time"),
      clientFrame: r.option("client frame", () => r.u32("client frame")),
      stateHash: r.option("state hash", () => r.u64("state hash")),
      payload: r.bytesField("payload")
    };
  }
  function decodePayload(payload) {
    const r = new Reader(payload);
    const variant = r.u32("message kind");
    let m;
    switch (variant) {
      case 0:
        m = {
          kind: "hello",
          hello: {
            version: r.u16("version"),
            capabilities: r.u32("capabilities"),
            token: r.option("token", () => r.string("token")),
            name: r.string("name")
          }
        };
        break;
      case 1: {
        const w = {
          version: r.u16("version"),
          clientId: r.u32("client id"),
          codec: r.string("codec"),
          serverHz: r.u32("server hz"),
          clientHz: r.u32("client hz"),
          lockstep: r.bool("lockstep"),
          scene: r.string("scene"),
          frame: r.u64n("frame"),
          sceneTime: r.f64("scene time"),
          instances: []
        };
        const n = r.u32("instance count");
        if (n > r.rest() / 27) throw new WireError(`instance count ${n} exceeds the payload`);
        for (let i = 0; i < n; i++) w.instances.push(readInstance(r));
        finite("scene time", [w.sceneTime]);
        m = { kind: "welcome", welcome: w };
        break;
      }
      case 2: {
        const c = {
          frame: r.u32("frame"),
          position: r.vec3("position"),
          target: r.vec3("target"),
          up: r.vec3("up"),
          fovY: r.f32("fov"),
          near: r.f32("near"),
          far: r.f32("far"),
          aspect: r.f32("aspect")
        };
        m = { kind: "camera", camera: c };
        break;
      }
      case 3:
        m = {
          kind: "scene_time",
          frame: r.u64n("frame"),
          seconds: r.f64("seconds"),
          clientFrame: r.option("client frame", () => r.u32("client frame"))
        };
        break;
      case 4:
        m = { kind: "ack", frame: r.u64n("frame") };
        break;
      case 5:
        m = { kind: "delta", delta: readDelta(r) };
        break;
      case 6:
        m = { kind: "snapshot", delta: readDelta(r) };
        break;
      case 7: {
        const code = r.u32("error code");
        if (code >= ERROR_CODES.length) throw new WireError(`unknown error code ${code}`);
        m = { kind: "error", code: ERROR_CODES[code], message: r.string("error message") };
        break;
      }
      case 8:
        m = { kind: "bye", reason: r.string("reason") };
        break;
      case 11:
        m = { kind: "status", stalled: r.bool("stalled"), text: r.string("status text") };
        break;
      default:
        throw new WireError(`unknown message kind ${variant}`);
    }
    if (!r.done()) throw new WireError(`${r.rest()} bytes after the message`);
    return m;
  }
  function decodeFrame(frame, limit = MAX_SERVER_FRAME) {
    if (frame.length < HEADER_LEN) throw new WireError(`truncated frame header (${frame.length} bytes)`);
    for (let i = 0; i < 4; i++) {
      if (frame[i] !== MAGIC[i]) throw new WireError("bad magic: not a psao frame");
    }
    const view = new DataView(frame.buffer, frame.byteOffset, frame.byteLength);
    const len = view.getUint32(4, true);
    const crc = view.getUint32(8, true);
    if (len > limit) throw new WireError(`payload of ${len} bytes exceeds the limit of ${limit}`);
    if (frame.length - HEADER_LEN < len) throw new WireError("truncated frame");
    if (frame.length - HEADER_LEN > len) throw new WireError("trailing bytes after the frame");
    const payload = frame.subarray(HEADER_LEN);
    if (crc32(payload) !== crc) throw new WireError("checksum mismatch");
    return decodePayload(payload);
  }
  function frameOf(payload) {
    const p = new Uint8Array(payload);
    const out = new Uint8Array(HEADER_LEN + p.length);
    out.set(MAGIC, 0);
    const view = new DataView(out.buffer);
    view.setUint32(4, p.length, true);
    view.setUint32(8, crc32(p), true);
    out.set(p, HEADER_LEN);
    return out;
  }
  function helloFrame(h) {
    const w = new Writer();
    w.varint(0);
    w.varint(h.version);
    w.varint(h.capabilities);
    w.bool(h.token !== null);
    if (h.token !== null) w.string(h.token);
    w.string(h.name);
    return frameOf(w.out);
  }
  function cameraFrame(c) {
    const w = new Writer();
    w.varint(2);
    w.varint(c.frame);
    for (const v of [...c.position, ...c.target, ...c.up, c.fovY, c.near, c.far, c.aspect]) w.f32(v);
    return frameOf(w.out);
  }
  function ackFrame(frame) {
    const w = new Writer();
    w.varint(4);
    w.varint(frame);
    return frameOf(w.out);
  }
  function byeFrame(reason) {
    const w = new Writer();
    w.varint(8);
    w.string(reason);
    return frameOf(w.out);
  }

  // src/session.ts
  var KEEP_ALIVE_MS = 5e3;
  function decodeLimit(table) {
    let total = 4096;
    for (const e of table) total += 64 + e.bucketCount * 110 + e.bucketCount * 8 * 40;
    return total;
  }
  var Session = class {
    constructor(opts, handler) {
      this.opts = opts;
      this.handler = handler;
      this.state = null;
      this.welcomeMsg = null;
      this.bytes = 0;
      this.updates = 0;
      this.mismatches = 0;
      this.lastHash = null;
      /// Milliseconds spent decoding and applying updates (hash checks excluded).
      this.decodeMs = 0;
      this.decoder = null;
      this.done = false;
      /// When the last frame went to the server (ms, `performance.now()`).
      this.lastSent = 0;
      this.lastAck = 0;
      this.keepAlive = null;
      this.ws = new WebSocket(opts.url);
      this.ws.binaryType = "arraybuffer";
      this.ws.onopen = () => {
        const caps = CAP_CODEC_COMPACT | CAP_STATUS | (opts.verify ? CAP_STATE_HASH : 0);
        this.send(helloFrame({ version: PROTOCOL_VERSION, capabilities: caps, token: opts.token, name: opts.name }));
        this.keepAlive = setInterval(() => {
          if (performance.now() - this.lastSent >= KEEP_ALIVE_MS) this.send(ackFrame(this.lastAck));
        }, KEEP_ALIVE_MS);
      };
      this.ws.onmessage = (ev) => {
        if (this.done) return;
        if (!(ev.data instanceof ArrayBuffer)) return this.fail("text WebSocket message (frames are binary)", true);
        const bytes = new Uint8Array(ev.data);
        this.bytes += bytes.length;
        try {
          this.handle(decodeFrame(bytes), bytes.length);
        } catch (e) {
          this.fail(`bad frame from the server: ${e.message}`, true);
        }
      };
      this.ws.onclose = () => this.end("the connection closed", false);
      this.ws.onerror = () => this.end("the connection failed", false);
    }
    handle(m, size) {
      switch (m.kind) {
        case "welcome": {
          const w = m.welcome;
          if (w.version !== PROTOCOL_VERSION) {
            return this.fail(`the server speaks protocol version ${w.version}, this viewer ${PROTOCOL_VERSION}`, true);
          }
          if (w.codec !== "compact") return this.fail(`the server's codec \`${w.codec}\` is not supported`, true);
          this.welcomeMsg = w;
          this.state = new ClientState(w.instances);
          this.decoder = new CompactDecoder(
            decodeLimit(w.instances),
            w.instances.map((e) => e.bucketCount),
            this.state
          );
          this.handler.welcome(w);
          return;
        }
        case "delta":
        case "snapshot": {
          if (!this.decoder || !this.state) return this.fail("update before the welcome", true);
          const t0 = performance.now();
          const u = this.decoder.decode(m.delta.payload);
          if (u.snapshot !== (m.kind === "snapshot")) {
            return this.fail("the update's snapshot flag does not match its message", true);
          }
          this.state.apply(u);
          this.decodeMs += performance.now() - t0;
          this.updates++;
          let verified = false;
          if (m.delta.stateHash !== null) {
            this.lastHash = this.state.stateHash();
            verified = this.lastHash === m.delta.stateHash;
            if (!verified) this.mismatches++;
          }
          this.lastAck = m.delta.frame;
          this.send(ackFrame(m.delta.frame));
          this.handler.update(u, size, verified);
          this.handler.sceneTime?.(m.delta.frame, m.delta.clientFrame, m.delta.sceneTime);
          return;
        }
        case "scene_time":
          this.handler.sceneTime?.(m.frame, m.clientFrame, m.seconds);
          return;
        case "error": {
          const fatal = m.code === "Token" || m.code === "Version";
          const text = m.code === "Token" ? `wrong or missing token: ${m.message}` : m.code === "Version" ? `protocol version mismatch: ${m.message}` : `server error (${m.code}): ${m.message}`;
          return this.fail(text, fatal);
        }
        case "bye":
          return this.end(`the server said bye: ${m.reason}`, false);
        case "status":
          this.handler.status?.(m.stalled ? m.text : null);
          return;
        default:
          return this.fail(`unexpected ${m.kind} from the server`, true);
      }
    }
    /// Sends the client's camera.
    sendCamera(c) {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.send(cameraFrame(c));
    }
    send(frame) {
      this.lastSent = performance.now();
      this.ws.send(frame);
    }
    /// Ends the session with a bye.
    close() {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.send(byeFrame("done"));
      this.end("closed by the viewer", true);
      this.ws.close();
    }
    fail(reason, fatal) {
      this.end(reason, fatal);
      this.ws.close();
    }
    end(reason, fatal) {
      if (this.done) return;
      this.done = true;
      if (this.keepAlive !== null) clearInterval(this.keepAlive);
      this.handler.closed(reason, fatal);
    }
  };

  // src/bounds.ts
  function sceneBounds(glb) {
    const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
    if (glb.length < 20 || view.getUint32(0, true) !== 1179937895) return null;
    const jsonLen = view.getUint32(12, true);
    if (view.getUint32(16, true) !== 1313821514 || 20 + jsonLen > glb.length) return null;
    const doc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
    const lo = [Infinity, Infinity, Infinity];
    const hi = [-Infinity, -Infinity, -Infinity];
    for (const node of doc.nodes ?? []) {
      if (node.mesh === void 0 || !node.matrix) continue;
      const m = node.matrix;
      for (const prim of doc.meshes?.[node.mesh]?.primitives ?? []) {
        const acc = prim.attributes.POSITION !== void 0 ? doc.accessors?.[prim.attributes.POSITION] : void 0;
        if (!acc?.min || !acc.max) continue;
        for (let corner = 0; corner < 8; corner++) {
          const p = [0, 1, 2].map((k) => corner >> k & 1 ? acc.max[k] : acc.min[k]);
          for (let r = 0; r < 3; r++) {
            const v = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r];
            lo[r] = Math.min(lo[r], v);
            hi[r] = Math.max(hi[r], v);
          }
        }
      }
    }
    if (!(lo[0] <= hi[0])) return null;
    const centre = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2);
    const radius = Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2, 1e-3);
    return { centre, radius };
  }

  // src/grids.ts
  var TEX_WIDTH = 1024;
  var CELL_PAGE = 32;
  var NO_PAGE = 4294967295;
  var MAX_POOL_TEXELS = 1 << 28;
  var DataTexture = class {
    constructor(gl2, channels) {
      this.gl = gl2;
      this.channels = channels;
      /// The texture (immutable storage: growing makes a new one).
      this.texture = null;
      this.mirror = new Uint32Array(0);
      this.rows = 0;
      this.dirty = new Uint8Array(0);
      this.anyDirty = false;
      this.stale = true;
    }
    /// Words per texel.
    get words() {
      return this.channels;
    }
    /// Makes room for `texels` (rows doubling), keeping the contents; `fill` initialises new words.
    ensure(texels, fill2 = 0) {
      const rows = Math.max(1, Math.ceil(texels / TEX_WIDTH));
      if (rows <= this.rows) return;
      const grown2 = Math.max(rows, 2 * this.rows);
      const mirror = new Uint32Array(grown2 * TEX_WIDTH * this.channels);
      mirror.set(this.mirror);
      if (fill2 !== 0) mirror.fill(fill2, this.mirror.length);
      this.mirror = mirror;
      this.rows = grown2;
      this.dirty = new Uint8Array(grown2).fill(1);
      this.anyDirty = true;
      this.stale = true;
    }
    /// Sets every word to `value` (rows kept, all dirty).
    reset(value) {
      this.mirror.fill(value);
      this.dirty.fill(1);
      this.anyDirty = true;
    }
    /// Marks the rows of texels `first..first + count` for upload.
    touch(first, count) {
      const last = Math.floor((first + count - 1) / TEX_WIDTH);
      for (let r = Math.floor(first / TEX_WIDTH); r <= last; r++) this.dirty[r] = 1;
      this.anyDirty = true;
    }
    /// Bytes of texture storage.
    bytes() {
      return this.mirror.byteLength;
    }
    /// (Re)creates the texture when it grew, then uploads runs of dirty rows; returns the
    /// bytes uploaded.
    upload() {
      const gl2 = this.gl;
      if (this.rows === 0) return 0;
      if (this.stale) {
        this.stale = false;
        if (this.texture) gl2.deleteTexture(this.texture);
        this.texture = gl2.createTexture();
        gl2.bindTexture(gl2.TEXTURE_2D, this.texture);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
        gl2.texStorage2D(gl2.TEXTURE_2D, 1, this.channels === 1 ? gl2.R32UI : gl2.RGBA32UI, TEX_WIDTH, this.rows);
      }
      if (!this.anyDirty) return 0;
      gl2.bindTexture(gl2.TEXTURE_2D, this.texture);
      const format = this.channels === 1 ? gl2.RED_INTEGER : gl2.RGBA_INTEGER;
      const rowWords = TEX_WIDTH * this.channels;
      let bytes = 0;
      for (let r = 0; r < this.rows; ) {
        if (!this.dirty[r]) {
          r++;
          continue;
        }
        let end = r;
        while (end < this.rows && this.dirty[end]) this.dirty[end++] = 0;
        const data = this.mirror.subarray(r * rowWords, end * rowWords);
        gl2.texSubImage2D(gl2.TEXTURE_2D, 0, 0, r, TEX_WIDTH, end - r, format, gl2.UNSIGNED_INT, data);
        bytes += data.byteLength;
        r = end;
      }
      this.anyDirty = false;
      return bytes;
    }
  };
  var ChunkPool = class {
    constructor() {
      this.end = 0;
      this.free = [[], [], [], []];
    }
    /// Forgets every chunk.
    clear() {
      this.end = 0;
      for (const f of this.free) f.length = 0;
    }
    /// A chunk of size class `c` (2^c texels); returns its first texel.
    alloc(c) {
      const reused = this.free[c].pop();
      if (reused !== void 0) return reused;
      const first = this.end;
      this.end += 1 << c;
      return first;
    }
    release(first, c) {
      this.free[c].push(first);
    }
    /// Texels in use or free (the pool's high-water mark).
    get texels() {
      return this.end;
    }
  };
  function sizeClass(count) {
    return count <= 1 ? 0 : count <= 2 ? 1 : count <= 4 ? 2 : 3;
  }
  var GridTextures = class {
    constructor(gl2) {
      this.gl = gl2;
      this.slots = [];
      /// Why AO cannot be drawn (textures too large), or null.
      this.problem = null;
      /// Bytes uploaded so far and full rebuilds.
      this.uploadedBytes = 0;
      this.rebuilds = 0;
      this.state = null;
      this.stale = true;
      this.pool = new ChunkPool();
      /// Pages of cells allocated (0 until the grids hold points).
      this.cellPages = 0;
      this.directory = new DataTexture(gl2, 1);
      this.entries = new DataTexture(gl2, 4);
      this.pageTable = new DataTexture(gl2, 1);
      this.cells = new DataTexture(gl2, 4);
    }
    /// Follows a new session's (empty) state: lays out its directory and page table.
    reset(state) {
      this.state = state;
      this.stale = true;
      let buckets = 0;
      let pages = 0;
      this.slots = state.grids.map((g) => {
        if (!g) return null;
        const s = { bucketBase: buckets, cellPageBase: pages, maxCells: g.maxCells() };
        buckets += g.entry.bucketCount;
        pages += Math.ceil(g.maxCells() / CELL_PAGE);
        return s;
      });
      const maxRows = this.gl.getParameter(this.gl.MAX_TEXTURE_SIZE);
      const rows = Math.ceil(Math.max(buckets, pages) / TEX_WIDTH);
      this.problem = rows > maxRows ? `the grids need ${rows} texture rows, this GPU allows ${maxRows}: AO not drawn` : null;
      if (this.problem) {
        this.slots = state.grids.map(() => null);
        return;
      }
      this.directory.ensure(buckets);
      this.pageTable.ensure(pages, NO_PAGE);
    }
    /// Mirrors one applied update (call after `state.apply(u)`).
    apply(u) {
      const state = this.state;
      if (!state || this.stale || u.snapshot || this.problem) {
        this.stale = true;
        return;
      }
      for (const d of u.instances) {
        const slot = this.slots[d.instance];
        const grid = state.grids[d.instance];
        if (!slot || !grid) continue;
        for (let k = 0; k < d.bucketIds.length; k++) this.setBucket(grid, slot, d.bucketIds[k]);
        for (let k = 0; k < d.cellSlots.length; k++) this.setCell(grid, slot, d.cellSlots[k]);
      }
    }
    /// Brings the textures up to date (a full rebuild when needed) and binds nothing.
    upload() {
      if (this.problem) return;
      if (this.stale && this.state) this.rebuild(this.state);
      this.uploadedBytes += this.directory.upload() + this.entries.upload() + this.pageTable.upload() + this.cells.upload();
    }
    /// Bytes of texture storage in use.
    textureBytes() {
      return this.directory.bytes() + this.entries.bytes() + this.pageTable.bytes() + this.cells.bytes();
    }
    /// Bucket `b` of `grid` as the state holds it: its used entries into a chunk of the pool.
    setBucket(grid, slot, b) {
      const at = slot.bucketBase + b;
      const dir = this.directory.mirror;
      const old = dir[at];
      const oldCount = old & 15;
      const base = b * BUCKET_ENTRIES;
      let count = 0;
      for (let e = 0; e < BUCKET_ENTRIES; e++) if (grid.keyLo[base + e] !== 0 || grid.keyHi[base + e] !== 0) count++;
      let first = old >>> 4;
      if (oldCount > 0 && (count === 0 || sizeClass(count) !== sizeClass(oldCount))) {
        this.pool.release(first, sizeClass(oldCount));
      }
      if (count > 0 && (oldCount === 0 || sizeClass(count) !== sizeClass(oldCount))) {
        first = this.pool.alloc(sizeClass(count));
        if (this.pool.texels > MAX_POOL_TEXELS) {
          this.problem = "the bucket entries outgrew the entry pool: AO not drawn";
          return;
        }
        this.entries.ensure(this.pool.texels);
      }
      const m = this.entries.mirror;
      let o = first * 4;
      for (let e = 0; e < BUCKET_ENTRIES; e++) {
        const lo = grid.keyLo[base + e];
        const hi = grid.keyHi[base + e];
        if (lo === 0 && hi === 0) continue;
        m[o] = lo;
        m[o + 1] = hi;
        m[o + 2] = grid.slots[base + e];
        o += 4;
      }
      if (count > 0) this.entries.touch(first, count);
      dir[at] = count === 0 ? 0 : (first << 4 | count) >>> 0;
      this.directory.touch(at, 1);
    }
    /// Cell slot `s` of `grid` as the state holds it, into its page (allocated when it first
    /// holds points).
    setCell(grid, slot, s) {
      if (s >= slot.maxCells) return;
      const at = slot.cellPageBase + Math.floor(s / CELL_PAGE);
      const table = this.pageTable.mirror;
      let page = table[at];
      const src = s * CELL_POINTS;
      if (page === NO_PAGE) {
        let any = false;
        for (let i = 0; i < CELL_POINTS; i++) if (grid.points[src + i] !== 0) any = true;
        if (!any) return;
        page = this.cellPages++;
        table[at] = page;
        this.pageTable.touch(at, 1);
        this.cells.ensure(2 * CELL_PAGE * this.cellPages);
      }
      const texel = 2 * (page * CELL_PAGE + s % CELL_PAGE);
      const m = this.cells.mirror;
      for (let i = 0; i < CELL_POINTS; i++) m[texel * 4 + i] = grid.points[src + i] ?? 0;
      m[texel * 4 + 7] = 0;
      this.cells.touch(texel, 2);
    }
    rebuild(state) {
      this.stale = false;
      this.rebuilds++;
      this.pool.clear();
      this.cellPages = 0;
      this.directory.reset(0);
      this.pageTable.reset(NO_PAGE);
      state.grids.forEach((g, k) => {
        const slot = this.slots[k];
        if (!g || !slot) return;
        const n = g.entry.bucketCount * BUCKET_ENTRIES;
        for (let e = 0; e < n; e++) {
          if (g.keyLo[e] === 0 && g.keyHi[e] === 0) continue;
          const b = Math.floor(e / BUCKET_ENTRIES);
          this.setBucket(g, slot, b);
          e = (b + 1) * BUCKET_ENTRIES - 1;
        }
        for (let s = 0; s < g.slotCount; s++) this.setCell(g, slot, s);
      });
    }
  };

  // src/skin.ts
  var JOINT_TEXELS = 7;
  var Animation = class {
    constructor(doc, instances, read) {
      this.clips = [];
      this.rigs = [];
      const nodes = doc.nodes ?? [];
      this.rest = nodes.map((n) => ({ t: n.translation ?? [0, 0, 0], r: n.rotation ?? [0, 0, 0, 1], s: n.scale ?? [1, 1, 1] }));
      this.parents = nodes.map(() => null);
      nodes.forEach((n, p) => n.children?.forEach((c) => this.parents[c] = p));
      this.order = parentsFirst(this.parents);
      for (const a of (doc.extras?.psao_playing ?? []).map((k) => doc.animations?.[k])) {
        if (!a) continue;
        const channels = [];
        for (const ch of a.channels) {
          const s = a.samplers[ch.sampler];
          if (!s || ch.target.node === void 0 || !["translation", "rotation", "scale"].includes(ch.target.path)) continue;
          channels.push({
            node: ch.target.node,
            path: ch.target.path,
            interpolation: s.interpolation ?? "LINEAR",
            times: Float32Array.from(read(s.input)),
            values: Float32Array.from(read(s.output))
          });
        }
        const duration = channels.reduce((d, c) => Math.max(d, c.times.length ? c.times[c.times.length - 1] : 0), 0);
        this.clips.push({ duration, channels });
      }
      this.jointBase = new Int32Array(instances).fill(-1);
      let base = 0;
      for (let i = 0; i < Math.min(instances, nodes.length); i++) {
        const n = nodes[i];
        const skin = n.skin !== void 0 ? doc.skins?.[n.skin] : void 0;
        if (!n.extras?.psao_skinned || !skin) continue;
        const ibm = skin.inverseBindMatrices !== void 0 ? read(skin.inverseBindMatrices) : null;
        const inverseBind = skin.joints.map(
          (_, j) => ibm ? Float64Array.from(ibm.subarray(16 * j, 16 * j + 16)) : identity()
        );
        this.rigs.push({
          instance: i,
          joints: skin.joints,
          inverseBind,
          node: n.extras.psao_node ?? null,
          rest: Float64Array.from(n.matrix ?? identity()),
          base
        });
        this.jointBase[i] = base;
        base += skin.joints.length;
      }
      this.jointCount = base;
    }
    /// Whether any instance is skinned.
    get skinned() {
      return this.rigs.length > 0;
    }
    /// Every rig's joint matrices at scene time `time` (seconds), `JOINT_TEXELS` RGBA texels
    /// per joint from `jointBase[instance]`.
    jointTexels(time) {
      const world = this.worlds(time);
      const out = new Float32Array(Math.max(1, this.jointCount) * JOINT_TEXELS * 4);
      for (const rig of this.rigs) {
        const own = rig.node !== null && world[rig.node] ? world[rig.node] : rig.rest;
        const toLocal = invertOrIdentity(own);
        rig.joints.forEach((j, k) => {
          const m = mul(mul(toLocal, world[j] ?? identity()), rig.inverseBind[k]);
          const at = (rig.base + k) * JOINT_TEXELS * 4;
          out.set(m, at);
          out.set(normalMatrix(m), at + 16);
        });
      }
      return out;
    }
    /// World transforms of all nodes at `time` (psao-scene's `node_worlds`, without walkers).
    worlds(time) {
      const local = this.rest.map((n) => ({ t: n.t.slice(), r: n.r.slice(), s: n.s.slice() }));
      for (const clip of this.clips) {
        const t = clip.duration > 0 ? remEuclid(time, clip.duration) : 0;
        for (const ch of clip.channels) {
          const slot = local[ch.node];
          if (!slot) continue;
          const v = sample(ch, t);
          if (ch.path === "rotation") slot.r = v;
          else if (ch.path === "scale") slot.s = v;
          else slot.t = v;
        }
      }
      const world = new Array(local.length);
      for (const n of this.order) {
        const l = trs(local[n].t, local[n].r, local[n].s);
        const p = this.parents[n];
        world[n] = p === null ? l : mul(world[p], l);
      }
      return world;
    }
  };
  function remEuclid(a, b) {
    const r = a % b;
    return r < 0 ? r + b : r;
  }
  function parentsFirst(parents) {
    const children = parents.map(() => []);
    parents.forEach((p, i) => p !== null && children[p]?.push(i));
    const order = parents.flatMap((p, i) => p === null ? [i] : []);
    for (let k = 0; k < order.length; k++) order.push(...children[order[k]]);
    return order;
  }
  function sample(ch, t) {
    const w = ch.path === "rotation" ? 4 : 3;
    const cubic = ch.interpolation === "CUBICSPLINE";
    const valueAt = (k, part = 1) => {
      const start = cubic ? (3 * k + part) * w : k * w;
      return Array.from(ch.values.subarray(start, start + w));
    };
    const times = ch.times;
    let next = 0;
    while (next < times.length && times[next] <= t) next++;
    let raw;
    if (next === 0) raw = valueAt(0);
    else if (next === times.length) raw = valueAt(times.length - 1);
    else {
      const k = next - 1;
      const dt = times[k + 1] - times[k];
      const s = (t - times[k]) / dt;
      if (ch.interpolation === "STEP") raw = valueAt(k);
      else if (ch.interpolation === "LINEAR") {
        if (ch.path === "rotation") return normalize(slerp(normalize(valueAt(k)), normalize(valueAt(k + 1)), s));
        const a = valueAt(k);
        const b = valueAt(k + 1);
        raw = a.map((x, i) => x + (b[i] - x) * s);
      } else {
        const p0 = valueAt(k);
        const m0 = valueAt(k, 2);
        const p1 = valueAt(k + 1);
        const m1 = valueAt(k + 1, 0);
        const s2 = s * s;
        const s3 = s2 * s;
        raw = p0.map(
          (_, i) => p0[i] * (2 * s3 - 3 * s2 + 1) + m0[i] * (dt * (s3 - 2 * s2 + s)) + p1[i] * (-2 * s3 + 3 * s2) + m1[i] * (dt * (s3 - s2))
        );
      }
    }
    if (ch.path !== "rotation") return raw;
    const len = Math.hypot(...raw);
    return len > 0 && Number.isFinite(len) ? raw.map((x) => x / len) : [0, 0, 0, 1];
  }
  function normalize(q) {
    const len = Math.hypot(...q);
    return q.map((x) => x / len);
  }
  function slerp(a, b, s) {
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    let e = b;
    if (dot < 0) {
      e = b.map((x) => -x);
      dot = -dot;
    }
    if (dot > 1 - 2 ** -23) return normalize(a.map((x, i) => x * (1 - s) + e[i] * s));
    const theta = acosApprox(dot);
    const s1 = Math.sin(theta * (1 - s));
    const s2 = Math.sin(theta * s);
    const inv = 1 / Math.sin(theta);
    return a.map((x, i) => (x * s1 + e[i] * s2) * inv);
  }
  function acosApprox(v) {
    const x = Math.abs(v);
    const root = Math.sqrt(Math.max(1 - x, 0));
    const r = ((((((-0.0012624911 * x + 667009e-8) * x - 0.017088126) * x + 0.03089188) * x - 0.050174303) * x + 0.08897899) * x - 0.2145988) * x + 1.5707963;
    return v >= 0 ? r * root : Math.PI - r * root;
  }
  function identity() {
    const m = new Float64Array(16);
    m[0] = m[5] = m[10] = m[15] = 1;
    return m;
  }
  function trs(t, q, s) {
    const [x, y, z, w] = q;
    const m = identity();
    const cols = [
      [1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)],
      [2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)],
      [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)]
    ];
    for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) m[4 * c + r] = cols[c][r] * s[c];
    m[12] = t[0];
    m[13] = t[1];
    m[14] = t[2];
    return m;
  }
  function mul(a, b) {
    const out = new Float64Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[4 * k + r] * b[4 * c + k];
        out[4 * c + r] = s;
      }
    }
    return out;
  }
  function det3(m) {
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[4] * (m[1] * m[10] - m[2] * m[9]) + m[8] * (m[1] * m[6] - m[2] * m[5]);
  }
  function inverse3(m) {
    const det = det3(m);
    if (!(det !== 0 && Number.isFinite(det))) return null;
    const [a, b, c, d, e, f, g, h, i] = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
    return [
      (e * i - f * h) / det,
      (c * h - b * i) / det,
      (b * f - c * e) / det,
      (f * g - d * i) / det,
      (a * i - c * g) / det,
      (c * d - a * f) / det,
      (d * h - e * g) / det,
      (b * g - a * h) / det,
      (a * e - b * d) / det
    ];
  }
  function invertOrIdentity(m) {
    const det = det3(m);
    if (!(m.every(Number.isFinite) && det !== 0 && Math.abs(det) >= 2 ** -126)) return identity();
    const inv = inverse3(m);
    const out = identity();
    for (let c = 0; c < 3; c++) for (let r = 0; r < 3; r++) out[4 * c + r] = inv[3 * c + r];
    for (let r = 0; r < 3; r++) out[12 + r] = -(inv[r] * m[12] + inv[3 + r] * m[13] + inv[6 + r] * m[14]);
    return out;
  }
  function normalMatrix(m) {
    const inv = inverse3(m);
    if (!inv || !inv.every(Number.isFinite)) return [m[0], m[1], m[2], 0, m[4], m[5], m[6], 0, m[8], m[9], m[10], 0];
    return [inv[0], inv[3], inv[6], 0, inv[1], inv[4], inv[7], 0, inv[2], inv[5], inv[8], 0];
  }

  // src/aoshader.ts
  var MODE_COMPOSITED = 0;
  var MODE_AO = 1;
  var MODE_NO_AO = 2;
  var MODE_COST = 3;
  var VERTEX = `#version 300 es
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in uvec4 joints;
layout(location = 3) in vec4 weights; // renormalised as psao-scene's BindMesh
uniform mat4 u_view_proj;
uniform mat4 u_model;
uniform mat3 u_normal_matrix;
// Skinned instances: their first joint in u_joints (JOINT_TEXELS RGBA32F texels per joint:
// the joint matrix's columns, then its normal matrix's), or -1.
uniform int u_joint_base;
uniform highp sampler2D u_joints;
out vec3 v_world;
out vec3 v_normal;
invariant gl_Position;

vec4 joint_texel(int i) { return texelFetch(u_joints, ivec2(i % ${TEX_WIDTH}, i / ${TEX_WIDTH}), 0); }

void main() {
  vec3 p = position;
  vec3 n = normal;
  if (u_joint_base >= 0) {
    // Linear blend skinning in mesh-local space (psao-scene's BindMesh::skin).
    vec3 sp = vec3(0.0);
    vec3 sn = vec3(0.0);
    for (int k = 0; k < 4; k++) {
      float w = weights[k];
      if (w > 0.0) {
        int at = (u_joint_base + int(joints[k])) * ${JOINT_TEXELS};
        mat4 m = mat4(joint_texel(at), joint_texel(at + 1), joint_texel(at + 2), joint_texel(at + 3));
        mat3 nm = mat3(joint_texel(at + 4).xyz, joint_texel(at + 5).xyz, joint_texel(at + 6).xyz);
        sp += w * (m * vec4(p, 1.0)).xyz;
        sn += w * (nm * n);
      }
    }
    p = sp;
    float l = length(sn);
    n = l > 0.0 ? sn / l : n;
  }
  vec4 world = u_model * vec4(p, 1.0);
  v_normal = u_normal_matrix * n;
  v_world = world.xyz;
  gl_Position = u_view_proj * world;
}`;
  var GBUFFER = `#version 300 es
precision highp float;
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_eye;
uniform float u_instance;
uniform float u_colour_index;
layout(location = 0) out vec4 out_position;
layout(location = 1) out vec4 out_normal;

void main() {
  // The face normal turned towards the eye, and the shading normal in its hemisphere
  // (psao-raster's resolve).
  vec3 g = cross(dFdx(v_world), dFdy(v_world));
  float glen = length(g);
  vec3 to_eye = u_eye - v_world;
  g = glen > 0.0 ? g / glen : normalize(to_eye);
  if (dot(g, to_eye) < 0.0) g = -g;
  float sl = length(v_normal);
  vec3 n = sl > 0.0 ? v_normal / sl : g;
  if (dot(n, g) < 0.0) n = -n;
  out_position = vec4(v_world, u_instance);
  out_normal = vec4(n, u_colour_index);
}`;
  var FULLSCREEN = `#version 300 es
void main() {
  vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}`;
  var FRAGMENT = `#version 300 es
precision highp float;
precision highp int;
precision highp usampler2D;
out vec4 out_colour;

uniform int u_mode;
uniform int u_scale;
uniform highp sampler2D u_gposition;
uniform highp sampler2D u_gnormal;
uniform highp sampler2D u_colours; // base colour by index
uniform vec3 u_sky;
uniform vec3 u_light_dir;
uniform float u_light;
uniform float u_ambient;

// Per instance (one row each, see grids.ts' instanceRows): its view (has_view false: AO 1,
// as psao-client without a grid or an invertible transform) and grid layout.
uniform highp sampler2D u_instf;
uniform usampler2D u_instu;
bool u_has_view;
bool u_has_cells; // false: the grid holds no cell yet (every lookup would miss: AO 1)
mat4 u_to_local;
mat3 u_normal_to_local;
vec3 u_origin;
float u_cell;
float u_inv_cell;
ivec3 u_dims;
float u_poisson;
uint u_bucket_mask;
uint u_bucket_base;
uint u_cell_page_base;
uint u_cell_capacity;
uvec2 u_row;   // Dx\xB717 as (low, high) 32-bit halves
uvec2 u_slice; // Dx\xB7Dy\xB731
uniform usampler2D u_directory;  // per bucket: used entries | first pool texel << 4
uniform usampler2D u_entries;    // (key low, key high, slot, 0) per used entry
uniform usampler2D u_page_table; // per page of cell slots: its page in u_cells, or NO_PAGE
uniform usampler2D u_cells;
uniform highp sampler2D u_normals; // the 256 decoded normal codes

// Reconstruction settings (psao-client's ReconstructSettings, psao-points' thresholds).
uniform float u_factor;
uniform float u_plane_tolerance;
uniform float u_normal_threshold;
uniform float u_direction_threshold;
uniform int u_exponent;
uniform bool u_fallback;

const uint WIDTH = ${TEX_WIDTH}u;
const uint CELL_PAGE = ${CELL_PAGE}u;
const uint NO_PAGE = ${NO_PAGE}u;

ivec2 at(uint i) { return ivec2(int(i % WIDTH), int(i / WIDTH)); }

// The 64-bit product of two 32-bit words, from 16-bit limbs, as (low, high).
uvec2 mul32(uint a, uint b) {
  uint a0 = a & 0xFFFFu, a1 = a >> 16, b0 = b & 0xFFFFu, b1 = b >> 16;
  uint p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
  uint mid = (p00 >> 16) + (p01 & 0xFFFFu) + (p10 & 0xFFFFu);
  return uvec2((mid << 16) | (p00 & 0xFFFFu), p11 + (p01 >> 16) + (p10 >> 16) + (mid >> 16));
}
uvec2 add64(uvec2 a, uvec2 b) {
  uint lo = a.x + b.x;
  return uvec2(lo, a.y + b.y + (lo < a.x ? 1u : 0u));
}
uvec2 mul64(uint s, uvec2 v) { return add64(mul32(s, v.x), uvec2(0u, s * v.y)); }

// Per pixel: the shaded point and the running sums.
vec3 P, N;
float R, R2, INV_R, PLANE;
float w_sum, ao_sum, nearest_d2, nearest_ao;
int cells_visited, points_visited;

// The slot of allocated cell c (InstanceGrid::find_cell), or -1.
int find_cell(ivec3 c) {
  if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, u_dims))) return -1;
  uvec3 u = uvec3(c);
  uvec2 id = add64(add64(uvec2(u.x, 0u), mul64(u.y, u_row)), mul64(u.z, u_slice));
  uvec2 key = add64(id, uvec2(1u, 0u));
  uint dir = texelFetch(u_directory, at(u_bucket_base + (id.x & u_bucket_mask)), 0).x;
  uint first = dir >> 4;
  uint count = dir & 15u;
  for (uint e = 0u; e < count; e++) {
    uvec4 t = texelFetch(u_entries, at(first + e), 0);
    if (t.x == key.x && t.y == key.y) return t.z < u_cell_capacity ? int(t.z) : -1;
  }
  return -1;
}

float pow_k(float x) {
  float y = 1.0;
  for (int i = 0; i < u_exponent; i++) y *= x;
  return y;
}

// One packed point of cell c: the block pass weights it and tracks the nearest compatible
// point; the ring pass only tracks the nearest.
void point(uint bits, vec3 cell_min, bool weigh) {
  if ((bits & 0x80000000u) == 0u) return;
  points_visited++;
  vec3 frac = (vec3((uvec3(bits >> 26, bits >> 21, bits >> 16)) & 31u) + 0.5) * (1.0 / 32.0);
  vec3 delta = (u_origin + (cell_min + frac) * u_cell) - P;
  vec3 ni = texelFetch(u_normals, ivec2(int((bits >> 8) & 255u), 0), 0).xyz;
  float d2 = dot(delta, delta);
  float c = dot(ni, delta) / sqrt(d2);
  float nn = dot(ni, N);
  bool compatible = nn > u_normal_threshold && abs(dot(N, delta)) <= PLANE &&
                    (d2 == 0.0 || c * c < u_direction_threshold);
  if (!compatible) return;
  float ao = float(bits & 255u) * (1.0 / 255.0);
  if (weigh && d2 < R2) {
    float w = (R - sqrt(d2)) * INV_R * pow_k(nn);
    w_sum += w;
    ao_sum += w * ao;
  }
  if (d2 < nearest_d2) {
    nearest_d2 = d2;
    nearest_ao = ao;
  }
}

void cell(ivec3 c, bool weigh) {
  int slot = find_cell(c);
  if (slot < 0) return;
  cells_visited++;
  uint page = texelFetch(u_page_table, at(u_cell_page_base + uint(slot) / CELL_PAGE), 0).x;
  if (page == NO_PAGE) return;
  uint t = 2u * (page * CELL_PAGE + uint(slot) % CELL_PAGE);
  uvec4 a = texelFetch(u_cells, at(t), 0);
  uvec4 b = texelFetch(u_cells, at(t + 1u), 0);
  vec3 m = vec3(c);
  point(a.x, m, weigh); point(a.y, m, weigh); point(a.z, m, weigh); point(a.w, m, weigh);
  point(b.x, m, weigh); point(b.y, m, weigh); point(b.z, m, weigh);
}

void load_instance(int i) {
  vec4 f[9];
  for (int k = 0; k < 9; k++) f[k] = texelFetch(u_instf, ivec2(k, i), 0);
  u_to_local = mat4(f[0], f[1], f[2], f[3]);
  u_normal_to_local = mat3(f[4].xyz, f[5].xyz, f[6].xyz);
  u_origin = f[7].xyz;
  u_cell = f[7].w;
  u_inv_cell = f[8].x;
  u_poisson = f[8].y;
  u_has_view = f[8].z > 0.5;
  uvec4 a = texelFetch(u_instu, ivec2(0, i), 0);
  uvec4 b = texelFetch(u_instu, ivec2(1, i), 0);
  uvec4 c = texelFetch(u_instu, ivec2(2, i), 0);
  u_dims = ivec3(a.xyz);
  u_bucket_mask = a.w;
  u_bucket_base = b.x;
  u_cell_page_base = b.y;
  u_cell_capacity = b.z;
  u_has_cells = b.w != 0u;
  u_row = c.xy;
  u_slice = c.zw;
}

float reconstruct(vec3 world, vec3 normal) {
  // Without cells psao-client finds no point in the block nor in the ring: AO 1, decided
  // here without the 64 lookups (which made every frame cost the most before any points).
  if (!u_has_view || !u_has_cells) return 1.0;
  P = (u_to_local * vec4(world, 1.0)).xyz;
  vec3 n = u_normal_to_local * normal;
  float l = length(n);
  N = l > 0.0 ? n / l : vec3(0.0);
  R = u_poisson * u_factor;
  if (!(R > 0.0)) return 1.0;
  R2 = R * R;
  INV_R = 1.0 / R;
  PLANE = u_plane_tolerance * u_poisson;
  w_sum = 0.0;
  ao_sum = 0.0;
  nearest_d2 = 3.4e38;
  nearest_ao = -1.0;
  ivec3 base = ivec3(floor((P - u_origin) * u_inv_cell - 0.5));
  for (int k = 0; k < 8; k++) cell(base + ivec3(k & 1, (k >> 1) & 1, k >> 2), true);
  if (w_sum > 0.0) return ao_sum / w_sum;
  if (!u_fallback) return 1.0;
  if (nearest_ao >= 0.0) return nearest_ao;
  for (int k = 0; k < 64; k++) {
    ivec3 o = ivec3(k & 3, (k >> 2) & 3, k >> 4) - 1;
    if (all(greaterThanEqual(o, ivec3(0))) && all(lessThanEqual(o, ivec3(1)))) continue;
    cell(base + o, false);
  }
  return nearest_ao >= 0.0 ? nearest_ao : 1.0;
}

float srgb(float linear) {
  float c = clamp(linear, 0.0, 1.0);
  return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

void main() {
  // This pixel's centre sample of the (scaled) G-buffer.
  ivec2 at_g = ivec2(gl_FragCoord.xy) * u_scale + u_scale / 2;
  vec4 gp = texelFetch(u_gposition, at_g, 0);
  vec4 gn = texelFetch(u_gnormal, at_g, 0);
  cells_visited = 0;
  points_visited = 0;
  if (gp.w < 0.0) {
    // Nothing covers the pixel: AO 1, no cost, the sky.
    out_colour = u_mode == ${MODE_AO} ? vec4(1.0) : u_mode == ${MODE_COST} ? vec4(0.0) : vec4(u_sky, 1.0);
    return;
  }
  vec3 n = gn.xyz;
  load_instance(int(gp.w));
  float ao = u_mode == ${MODE_NO_AO} ? 1.0 : reconstruct(gp.xyz, n);
  if (u_mode == ${MODE_AO}) {
    out_colour = vec4(vec3(ao), 1.0);
  } else if (u_mode == ${MODE_COST}) {
    out_colour = vec4(float(cells_visited), float(points_visited & 255), float(points_visited >> 8), 255.0) / 255.0;
  } else {
    vec3 colour = texelFetch(u_colours, ivec2(int(gn.w), 0), 0).rgb;
    vec3 rgb = colour * (u_ambient * ao + u_light * max(0.0, dot(n, u_light_dir)));
    out_colour = vec4(srgb(rgb.r), srgb(rgb.g), srgb(rgb.b), 1.0);
  }
}`;

  // src/render.ts
  var COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };
  function readAccessor(doc, bin, index) {
    const a = doc.accessors?.[index];
    const bv = a?.bufferView !== void 0 ? doc.bufferViews?.[a.bufferView] : void 0;
    if (!a || !bv) throw new Error(`scene.glb: accessor ${index} has no data`);
    const n = a.count * (COMPONENTS[a.type] ?? 1);
    const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
    const Kind = a.componentType === 5126 ? Float32Array : a.componentType === 5123 ? Uint16Array : Uint32Array;
    const bytes = bin.slice(start, start + n * Kind.BYTES_PER_ELEMENT);
    if (bytes.length !== n * Kind.BYTES_PER_ELEMENT) throw new Error(`scene.glb: accessor ${index} is truncated`);
    return new Kind(bytes.buffer);
  }
  function renormalisedWeights(w) {
    const out = new Float32Array(w.length);
    for (let v = 0; v + 4 <= w.length; v += 4) {
      const x = [0, 1, 2, 3].map((k) => Number.isFinite(w[v + k]) ? Math.max(w[v + k], 0) : 0);
      const sum = Math.fround(Math.fround(Math.fround(x[0] + x[1]) + x[2]) + x[3]);
      if (sum > 0) for (let k = 0; k < 4; k++) out[v + k] = x[k] / sum;
      else out[v] = 1;
    }
    return out;
  }
  var SETTINGS = {
    factor: Math.fround(2 * Math.SQRT2),
    planeTolerance: 0.5,
    normalThreshold: Math.fround(0.1),
    directionThreshold: Math.fround(0.7),
    exponent: 8,
    fallback: true,
    ambient: Math.fround(0.6),
    light: 0.5
  };
  var SKY_GREY = [0.62, 0.66, 0.72];
  var MIN_DETERMINANT = 1e-12;
  function encodeSrgb(linear) {
    const c = Math.min(Math.max(linear, 0), 1);
    const s = c <= 31308e-7 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
    return Math.round(s * 255);
  }
  function normalTable() {
    const f = Math.fround;
    const step = f(2 / 14);
    const level = (q) => f(f(Math.min(q, 14) * step) - 1);
    const sign = (x) => x >= 0 ? 1 : -1;
    const out = new Float32Array(256 * 4);
    for (let code = 0; code < 256; code++) {
      const ox = level(code >> 4);
      const oy = level(code & 15);
      const z = f(f(1 - Math.abs(ox)) - Math.abs(oy));
      let v;
      if (z >= 0) v = [ox, oy, z];
      else v = [f(f(1 - Math.abs(oy)) * sign(ox)), f(f(1 - Math.abs(ox)) * sign(oy)), z];
      const len = f(Math.sqrt(f(f(f(v[0] * v[0]) + f(v[1] * v[1])) + f(v[2] * v[2]))));
      const inv = f(1 / len);
      out.set([f(v[0] * inv), f(v[1] * inv), f(v[2] * inv), 0], code * 4);
    }
    return out;
  }
  function compile(gl2, type, source) {
    const s = gl2.createShader(type);
    gl2.shaderSource(s, source);
    gl2.compileShader(s);
    if (!gl2.getShaderParameter(s, gl2.COMPILE_STATUS)) throw new Error(`shader: ${gl2.getShaderInfoLog(s)}`);
    return s;
  }
  function instanceView(t) {
    const [a, b, c, d, e, f, g, h, i] = t;
    const det = a * (e * i - f * h) - d * (b * i - c * h) + g * (b * f - c * e);
    if (!(Math.abs(det) > MIN_DETERMINANT)) return null;
    const inv = [
      (e * i - f * h) / det,
      (c * h - b * i) / det,
      (b * f - c * e) / det,
      (f * g - d * i) / det,
      (a * i - c * g) / det,
      (c * d - a * f) / det,
      (d * h - e * g) / det,
      (b * g - a * h) / det,
      (a * e - b * d) / det
    ];
    const [tx, ty, tz] = [t[9], t[10], t[11]];
    const ix = -(inv[0] * tx + inv[3] * ty + inv[6] * tz);
    const iy = -(inv[1] * tx + inv[4] * ty + inv[7] * tz);
    const iz = -(inv[2] * tx + inv[5] * ty + inv[8] * tz);
    const toLocal = new Float32Array([inv[0], inv[1], inv[2], 0, inv[3], inv[4], inv[5], 0, inv[6], inv[7], inv[8], 0, ix, iy, iz, 1]);
    if (!toLocal.every(Number.isFinite)) return null;
    return { toLocal, normalToLocal: new Float32Array([a, d, g, b, e, h, c, f, i]) };
  }
  var GBufferTargets = class {
    constructor(gl2) {
      this.gl = gl2;
      this.position = null;
      this.normal = null;
      this.depth = null;
      this.width = 0;
      this.height = 0;
      this.fbo = gl2.createFramebuffer();
    }
    resize(width, height) {
      if (width === this.width && height === this.height) return;
      const gl2 = this.gl;
      this.width = width;
      this.height = height;
      for (const t of [this.position, this.normal]) if (t) gl2.deleteTexture(t);
      if (this.depth) gl2.deleteRenderbuffer(this.depth);
      const target = () => {
        const t = gl2.createTexture();
        gl2.bindTexture(gl2.TEXTURE_2D, t);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
        gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
        gl2.texStorage2D(gl2.TEXTURE_2D, 1, gl2.RGBA32F, width, height);
        return t;
      };
      this.position = target();
      this.normal = target();
      this.depth = gl2.createRenderbuffer();
      gl2.bindRenderbuffer(gl2.RENDERBUFFER, this.depth);
      gl2.renderbufferStorage(gl2.RENDERBUFFER, gl2.DEPTH_COMPONENT24, width, height);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, this.fbo);
      gl2.framebufferTexture2D(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT0, gl2.TEXTURE_2D, this.position, 0);
      gl2.framebufferTexture2D(gl2.FRAMEBUFFER, gl2.COLOR_ATTACHMENT1, gl2.TEXTURE_2D, this.normal, 0);
      gl2.framebufferRenderbuffer(gl2.FRAMEBUFFER, gl2.DEPTH_ATTACHMENT, gl2.RENDERBUFFER, this.depth);
      gl2.drawBuffers([gl2.COLOR_ATTACHMENT0, gl2.COLOR_ATTACHMENT1]);
      const status2 = gl2.checkFramebufferStatus(gl2.FRAMEBUFFER);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, null);
      if (status2 !== gl2.FRAMEBUFFER_COMPLETE) throw new Error(`G-buffer framebuffer incomplete (${status2})`);
    }
  };
  function program(gl2, vertex, fragment) {
    const p = gl2.createProgram();
    gl2.attachShader(p, compile(gl2, gl2.VERTEX_SHADER, vertex));
    gl2.attachShader(p, compile(gl2, gl2.FRAGMENT_SHADER, fragment));
    gl2.linkProgram(p);
    if (!gl2.getProgramParameter(p, gl2.LINK_STATUS)) throw new Error(`program: ${gl2.getProgramInfoLog(p)}`);
    const u = {};
    const count = gl2.getProgramParameter(p, gl2.ACTIVE_UNIFORMS);
    for (let i = 0; i < count; i++) {
      const name = gl2.getActiveUniform(p, i).name;
      u[name] = gl2.getUniformLocation(p, name);
    }
    return { p, u };
  }
  function dataTexture(gl2) {
    const t = gl2.createTexture();
    gl2.bindTexture(gl2.TEXTURE_2D, t);
    gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MIN_FILTER, gl2.NEAREST);
    gl2.texParameteri(gl2.TEXTURE_2D, gl2.TEXTURE_MAG_FILTER, gl2.NEAREST);
    return t;
  }
  var INST_F = 9;
  var INST_U = 3;
  var SceneRenderer = class {
    constructor(gl2, glb) {
      this.gl = gl2;
      this.meshes = [];
      this.instances = [];
      /// The scene's animation (skinned instances), when anything is skinned.
      this.animation = null;
      /// The scene's camera paths (from the glb's extras).
      this.paths = [];
      if (!gl2.getExtension("EXT_color_buffer_float")) throw new Error("WebGL2 without EXT_color_buffer_float");
      this.gbuffer = program(gl2, VERTEX, GBUFFER);
      this.shade = program(gl2, FULLSCREEN, FRAGMENT);
      this.targets = new GBufferTargets(gl2);
      this.normals = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, 256, 1, 0, gl2.RGBA, gl2.FLOAT, normalTable());
      this.instF = dataTexture(gl2);
      this.instU = dataTexture(gl2);
      this.emptyU = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32UI, 1, 1, 0, gl2.RGBA_INTEGER, gl2.UNSIGNED_INT, new Uint32Array(4));
      this.joints = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, 1, 1, 0, gl2.RGBA, gl2.FLOAT, new Float32Array(4));
      gl2.vertexAttribI4ui(2, 0, 0, 0, 0);
      const colours = this.load(glb);
      this.colours = dataTexture(gl2);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, Math.max(1, colours.length / 4), 1, 0, gl2.RGBA, gl2.FLOAT, colours.length ? colours : new Float32Array(4));
    }
    /// Uploads the meshes; returns the primitives' base colours (RGBA per colour index).
    load(glb) {
      const gl2 = this.gl;
      const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
      const jsonLen = view.getUint32(12, true);
      const doc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
      this.paths = doc.extras?.psao_camera_paths ?? [];
      const binAt = 20 + jsonLen + 8;
      const bin = glb.subarray(binAt, binAt + view.getUint32(20 + jsonLen, true));
      const data = (index) => {
        const a = doc.accessors[index];
        const bv = doc.bufferViews[a.bufferView];
        const width = { SCALAR: 1, VEC3: 3, VEC4: 4 }[a.type] ?? 1;
        const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
        return { bytes: bin.subarray(start, start + a.count * width * 4), count: a.count };
      };
      const instanceCount = (doc.nodes ?? []).findIndex((n) => n.mesh === void 0 || !n.matrix);
      const animation = new Animation(doc, instanceCount < 0 ? (doc.nodes ?? []).length : instanceCount, (i) => readAccessor(doc, bin, i));
      this.animation = animation.skinned ? animation : null;
      const colours = [];
      for (const mesh of doc.meshes ?? []) {
        const prims = [];
        for (const prim of mesh.primitives) {
          if (prim.attributes.POSITION === void 0 || prim.attributes.NORMAL === void 0 || prim.indices === void 0) continue;
          const vao = gl2.createVertexArray();
          gl2.bindVertexArray(vao);
          for (const [loc, acc] of [
            [0, prim.attributes.POSITION],
            [1, prim.attributes.NORMAL]
          ]) {
            const buf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, buf);
            gl2.bufferData(gl2.ARRAY_BUFFER, data(acc).bytes, gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(loc);
            gl2.vertexAttribPointer(loc, 3, gl2.FLOAT, false, 0, 0);
          }
          const { JOINTS_0: joints, WEIGHTS_0: weights } = prim.attributes;
          const skin = joints !== void 0 && weights !== void 0;
          if (skin) {
            const jbuf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, jbuf);
            gl2.bufferData(gl2.ARRAY_BUFFER, Uint16Array.from(readAccessor(doc, bin, joints)), gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(2);
            gl2.vertexAttribIPointer(2, 4, gl2.UNSIGNED_SHORT, 0, 0);
            const wbuf = gl2.createBuffer();
            gl2.bindBuffer(gl2.ARRAY_BUFFER, wbuf);
            gl2.bufferData(gl2.ARRAY_BUFFER, renormalisedWeights(readAccessor(doc, bin, weights)), gl2.STATIC_DRAW);
            gl2.enableVertexAttribArray(3);
            gl2.vertexAttribPointer(3, 4, gl2.FLOAT, false, 0, 0);
          }
          const idx = data(prim.indices);
          const ibo = gl2.createBuffer();
          gl2.bindBuffer(gl2.ELEMENT_ARRAY_BUFFER, ibo);
          gl2.bufferData(gl2.ELEMENT_ARRAY_BUFFER, idx.bytes, gl2.STATIC_DRAW);
          gl2.bindVertexArray(null);
          const c = doc.materials?.[prim.material ?? 0]?.pbrMetallicRoughness?.baseColorFactor ?? [0.8, 0.8, 0.8, 1];
          prims.push({ vao, count: idx.count, colour: colours.length / 4, skin });
          colours.push(c[0], c[1], c[2], 1);
        }
        this.meshes.push(prims);
      }
      for (const node of doc.nodes ?? []) {
        if (node.mesh === void 0 || !node.matrix) break;
        this.instances.push({ mesh: node.mesh, matrix: new Float32Array(node.matrix) });
      }
      return new Float32Array(colours);
    }
    /// Draws the scene from `camera` in `opts.mode`; instance i is drawn at
    /// `state.transforms[i]` when set (else its rest matrix), and its AO reconstructed from
    /// its grid when the state has its transform (as psao-client). The G-buffer is `scale`
    /// times the canvas size (1 by default; odd scales put a sample on every pixel centre).
    draw(camera, opts) {
      const gl2 = this.gl;
      const grids2 = opts.grids && !opts.grids.problem ? opts.grids : null;
      const state = opts.state;
      const scale2 = Math.max(1, Math.floor(opts.scale ?? 1));
      const w = gl2.drawingBufferWidth;
      const h = gl2.drawingBufferHeight;
      this.targets.resize(w * scale2, h * scale2);
      const g = this.gbuffer.u;
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, this.targets.fbo);
      gl2.viewport(0, 0, w * scale2, h * scale2);
      gl2.clearBufferfv(gl2.COLOR, 0, [0, 0, 0, -1]);
      gl2.clearBufferfv(gl2.COLOR, 1, [0, 0, 0, 0]);
      gl2.clearBufferfi(gl2.DEPTH_STENCIL, 0, 1, 0);
      gl2.enable(gl2.DEPTH_TEST);
      gl2.depthFunc(gl2.LESS);
      gl2.useProgram(this.gbuffer.p);
      const animation = this.animation;
      gl2.activeTexture(gl2.TEXTURE0);
      gl2.bindTexture(gl2.TEXTURE_2D, this.joints);
      if (animation) {
        const texels = animation.jointTexels(opts.time ?? 0);
        const rows2 = Math.ceil(texels.length / 4 / TEX_WIDTH);
        const padded = new Float32Array(rows2 * TEX_WIDTH * 4);
        padded.set(texels);
        gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, TEX_WIDTH, rows2, 0, gl2.RGBA, gl2.FLOAT, padded);
      }
      gl2.uniform1i(g.u_joints, 0);
      gl2.uniformMatrix4fv(g.u_view_proj, false, viewProj(camera));
      gl2.uniform3fv(g.u_eye, camera.position);
      const model = new Float32Array(16);
      const instF = new Float32Array(this.instances.length * INST_F * 4);
      const instU = new Uint32Array(this.instances.length * INST_U * 4);
      for (const [i, inst] of this.instances.entries()) {
        const t = state?.transforms[i] ?? null;
        if (t) {
          model.set([t[0], t[1], t[2], 0, t[3], t[4], t[5], 0, t[6], t[7], t[8], 0, t[9], t[10], t[11], 1]);
        } else {
          model.set(inst.matrix);
        }
        gl2.uniformMatrix4fv(g.u_model, false, model);
        gl2.uniformMatrix3fv(g.u_normal_matrix, false, normalMatrixOf(model));
        gl2.uniform1f(g.u_instance, i);
        const jointBase = animation ? animation.jointBase[i] : -1;
        for (const p of this.meshes[inst.mesh] ?? []) {
          gl2.uniform1f(g.u_colour_index, p.colour);
          gl2.uniform1i(g.u_joint_base, p.skin ? jointBase : -1);
          gl2.bindVertexArray(p.vao);
          gl2.drawElements(gl2.TRIANGLES, p.count, gl2.UNSIGNED_INT, 0);
        }
        this.instanceRow(i, t, state, grids2, instF, instU);
      }
      gl2.bindVertexArray(null);
      gl2.bindFramebuffer(gl2.FRAMEBUFFER, null);
      gl2.disable(gl2.DEPTH_TEST);
      const u = this.shade.u;
      gl2.viewport(0, 0, w, h);
      gl2.useProgram(this.shade.p);
      const rows = Math.max(1, this.instances.length);
      gl2.bindTexture(gl2.TEXTURE_2D, this.instF);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32F, INST_F, rows, 0, gl2.RGBA, gl2.FLOAT, instF.length ? instF : new Float32Array(INST_F * 4));
      gl2.bindTexture(gl2.TEXTURE_2D, this.instU);
      gl2.texImage2D(gl2.TEXTURE_2D, 0, gl2.RGBA32UI, INST_U, rows, 0, gl2.RGBA_INTEGER, gl2.UNSIGNED_INT, instU.length ? instU : new Uint32Array(INST_U * 4));
      const textures = [
        ["u_directory", grids2?.directory.texture ?? this.emptyU],
        ["u_entries", grids2?.entries.texture ?? this.emptyU],
        ["u_page_table", grids2?.pageTable.texture ?? this.emptyU],
        ["u_cells", grids2?.cells.texture ?? this.emptyU],
        ["u_normals", this.normals],
        ["u_gposition", this.targets.position],
        ["u_gnormal", this.targets.normal],
        ["u_colours", this.colours],
        ["u_instf", this.instF],
        ["u_instu", this.instU]
      ];
      textures.forEach(([name, t], unit) => {
        gl2.activeTexture(gl2.TEXTURE0 + unit);
        gl2.bindTexture(gl2.TEXTURE_2D, t);
        gl2.uniform1i(u[name], unit);
      });
      gl2.activeTexture(gl2.TEXTURE0);
      gl2.uniform1i(u.u_mode, opts.mode);
      gl2.uniform1i(u.u_scale, scale2);
      gl2.uniform3f(u.u_sky, ...SKY_GREY.map((c) => encodeSrgb(c) / 255));
      const l = [0.35, 1, 0.6];
      const ll = Math.hypot(l[0], l[1], l[2]);
      gl2.uniform3f(u.u_light_dir, l[0] / ll, l[1] / ll, l[2] / ll);
      gl2.uniform1f(u.u_light, SETTINGS.light);
      gl2.uniform1f(u.u_ambient, SETTINGS.ambient);
      gl2.uniform1f(u.u_factor, SETTINGS.factor);
      gl2.uniform1f(u.u_plane_tolerance, SETTINGS.planeTolerance);
      gl2.uniform1f(u.u_normal_threshold, SETTINGS.normalThreshold);
      gl2.uniform1f(u.u_direction_threshold, SETTINGS.directionThreshold);
      gl2.uniform1i(u.u_exponent, SETTINGS.exponent);
      gl2.uniform1i(u.u_fallback, SETTINGS.fallback ? 1 : 0);
      gl2.drawArrays(gl2.TRIANGLES, 0, 3);
    }
    /// Instance i's row of the instance textures: its view and grid layout.
    instanceRow(i, t, state, grids2, f, u) {
      const grid = state?.grids[i] ?? null;
      const slot = grids2?.slots[i] ?? null;
      const view = t && grid && slot ? instanceView(t) : null;
      if (!view || !grid || !slot) return;
      const e = grid.entry;
      const fo = i * INST_F * 4;
      f.set(view.toLocal, fo);
      const n = view.normalToLocal;
      f.set([n[0], n[1], n[2], 0, n[3], n[4], n[5], 0, n[6], n[7], n[8], 0], fo + 16);
      f.set([e.origin[0], e.origin[1], e.origin[2], e.cellSize, Math.fround(1 / e.cellSize), e.layoutPoissonRadius, 1, 0], fo + 28);
      const row = BigInt(e.dims[0]) * 17n;
      const slice = BigInt(e.dims[0]) * BigInt(e.dims[1]) * 31n;
      u.set(
        [
          e.dims[0],
          e.dims[1],
          e.dims[2],
          e.bucketCount - 1,
          slot.bucketBase,
          slot.cellPageBase,
          slot.maxCells,
          grid.slotCount > 0 ? 1 : 0,
          Number(row & 0xffffffffn),
          Number(row >> 32n),
          Number(slice & 0xffffffffn),
          Number(slice >> 32n)
        ],
        i * INST_U * 4
      );
    }
  };
  function normalMatrixOf(m) {
    const [a, b, c] = [m[0], m[1], m[2]];
    const [d, e, f] = [m[4], m[5], m[6]];
    const [g, h, i] = [m[8], m[9], m[10]];
    const det = a * (e * i - f * h) - d * (b * i - c * h) + g * (b * f - c * e) || 1;
    return [
      (e * i - f * h) / det,
      (f * g - d * i) / det,
      (d * h - e * g) / det,
      (c * h - b * i) / det,
      (a * i - c * g) / det,
      (b * g - a * h) / det,
      (b * f - c * e) / det,
      (c * d - a * f) / det,
      (a * e - b * d) / det
    ];
  }
  function viewProj(c) {
    const [px, py, pz] = c.position;
    let fx = c.target[0] - px;
    let fy = c.target[1] - py;
    let fz = c.target[2] - pz;
    const fl = Math.hypot(fx, fy, fz) || 1;
    fx /= fl;
    fy /= fl;
    fz /= fl;
    let sx = fy * c.up[2] - fz * c.up[1];
    let sy = fz * c.up[0] - fx * c.up[2];
    let sz = fx * c.up[1] - fy * c.up[0];
    const sl = Math.hypot(sx, sy, sz) || 1;
    sx /= sl;
    sy /= sl;
    sz /= sl;
    const ux = sy * fz - sz * fy;
    const uy = sz * fx - sx * fz;
    const uz = sx * fy - sy * fx;
    const view = [
      sx,
      ux,
      -fx,
      0,
      sy,
      uy,
      -fy,
      0,
      sz,
      uz,
      -fz,
      0,
      -(sx * px + sy * py + sz * pz),
      -(ux * px + uy * py + uz * pz),
      fx * px + fy * py + fz * pz,
      1
    ];
    const f = 1 / Math.tan(c.fovY / 2);
    const { near: n, far: fr } = c;
    const proj = [f / c.aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (fr + n) / (n - fr), -1, 0, 0, 2 * fr * n / (n - fr), 0];
    const out = new Float32Array(16);
    for (let col = 0; col < 4; col++) {
      for (let row = 0; row < 4; row++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += proj[k * 4 + row] * view[col * 4 + k];
        out[col * 4 + row] = s;
      }
    }
    return out;
  }

  // src/main.ts
  var status = {
    connected: false,
    sessions: 0,
    updates: 0,
    verified: 0,
    mismatches: 0,
    serverFrame: 0,
    points: 0,
    hash: null,
    message: null,
    fatal: false,
    stalled: null,
    mbitS: 0,
    fps: 0,
    drawn: 0,
    camera: null,
    autoOrbit: true,
    mode: MODE_COMPOSITED,
    edge: location.host,
    rttEdge: null,
    rttMs: null,
    path: null,
    pathFrame: 0,
    done: false,
    decodeMs: 0,
    uploadedBytes: 0,
    rebuilds: 0,
    textureBytes: 0,
    milestones: { scene: null, welcome: null, update: null, ao: null }
  };
  window.psao = status;
  var params = new URLSearchParams(location.search);
  var token = new URLSearchParams(location.hash.slice(1)).get("token");
  if (token !== null) history.replaceState(null, "", location.pathname + location.search);
  var verify = params.get("verify") === "1";
  var pathName = params.get("path");
  var orbitOnly = params.get("orbit") === "1";
  var testFrames = params.has("frames") ? Math.max(1, Number(params.get("frames"))) : null;
  var lockstep = params.get("lockstep") === "1";
  var fixedRes = /^(\d+)x(\d+)$/.exec(params.get("res") ?? "");
  var scale = Math.max(1, Math.floor(Number(params.get("scale") ?? "1")) | 1);
  var MODES = { composited: MODE_COMPOSITED, ao: MODE_AO, noao: MODE_NO_AO };
  status.mode = MODES[params.get("mode") ?? ""] ?? MODE_COMPOSITED;
  var edges = [location.host];
  for (const e of (params.get("edges") ?? "").split(",").map((e2) => e2.trim())) {
    if (/^[\w.-]+:\d+$|^\[[0-9a-fA-F:.]+\]:\d+$/.test(e) && !edges.includes(e)) edges.push(e);
  }
  var edgeIndex = 0;
  var wsUrl = (host) => `${location.protocol === "https:" ? "wss" : "ws"}://${host}/ws`;
  var session = null;
  var backoff = 200;
  var received = [];
  function connect() {
    status.edge = edges[edgeIndex];
    session = new Session(
      { url: wsUrl(status.edge), token, verify, name: "psao browser viewer" },
      {
        welcome: () => {
          var _a;
          (_a = status.milestones).welcome ?? (_a.welcome = performance.now());
          status.connected = true;
          status.sessions++;
          status.message = null;
          status.stalled = null;
          backoff = 200;
          if (session?.state) grids?.reset(session.state);
          pathFrame = 0;
          answered = -1;
          sent = -1;
        },
        sceneTime: (_frame, clientFrame, seconds) => {
          if (clientFrame !== null) answered = Math.max(answered, clientFrame);
          serverTime = { seconds, at: performance.now() };
        },
        update: (u, bytes, verified) => {
          var _a;
          (_a = status.milestones).update ?? (_a.update = performance.now());
          grids?.apply(u);
          status.updates++;
          if (verified) status.verified++;
          status.mismatches = session?.mismatches ?? status.mismatches;
          status.serverFrame = Number(u.frame);
          received.push({ t: performance.now(), bytes });
          if (session?.lastHash != null) status.hash = session.lastHash.toString(16).padStart(16, "0");
        },
        status: (text) => status.stalled = text,
        closed: (reason, fatal) => {
          status.connected = false;
          status.message = reason;
          status.fatal = fatal;
          if (!fatal) {
            edgeIndex = (edgeIndex + 1) % edges.length;
            setTimeout(connect, backoff);
            backoff = Math.min(backoff * 2, 5e3);
          }
        }
      }
    );
  }
  var overlay = document.getElementById("overlay");
  var message = document.getElementById("message");
  var frames = [];
  var cameraFrame2 = 0;
  var orbit = null;
  function countPoints() {
    let n = 0;
    for (const g of session?.state?.grids ?? []) {
      if (!g) continue;
      const p = g.points;
      for (let i = 0; i < g.slotCount * 7; i++) if (p[i] >>> 31) n++;
    }
    return n;
  }
  var canvas = document.getElementById("view");
  var gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
  var renderer = null;
  var grids = gl ? new GridTextures(gl) : null;
  var path = null;
  var pathFrame = 0;
  var sent = -1;
  var answered = -1;
  var pathStart = 0;
  var serverTime = null;
  function sceneTime(now) {
    if (lockstep && testFrames !== null) return Math.max(answered, 0) / 60;
    return serverTime ? serverTime.seconds + (now - serverTime.at) / 1e3 : 0;
  }
  for (const [id, mode] of [
    ["mode-composited", MODE_COMPOSITED],
    ["mode-ao", MODE_AO],
    ["mode-noao", MODE_NO_AO]
  ]) {
    document.getElementById(id)?.addEventListener("click", () => status.mode = mode);
  }
  var control = { auto: true, yaw: 0, pitch: 0.3, distance: 0, keys: /* @__PURE__ */ new Set(), last: 0 };
  canvas.addEventListener("mousedown", (e) => {
    control.auto = false;
    const move = (m) => {
      control.yaw += m.movementX * 5e-3;
      control.pitch = Math.max(-1.5, Math.min(1.5, control.pitch + m.movementY * 5e-3));
    };
    const up = () => {
      window.removeEventListener("mousemove", move);
      window.removeEventListener("mouseup", up);
    };
    window.addEventListener("mousemove", move);
    window.addEventListener("mouseup", up);
    e.preventDefault();
  });
  canvas.addEventListener(
    "wheel",
    (e) => {
      control.auto = false;
      const r = orbit?.radius ?? 1;
      control.distance = Math.max(r * 0.01, Math.min(r * 20, control.distance * Math.exp(e.deltaY * 1e-3)));
      e.preventDefault();
    },
    { passive: false }
  );
  window.addEventListener("keydown", (e) => {
    if (e.key === "1") status.mode = MODE_COMPOSITED;
    else if (e.key === "2") status.mode = MODE_AO;
    else if (e.key === "3") status.mode = MODE_NO_AO;
    else if (e.key === " ") control.auto = true;
    else control.keys.add(e.key.toLowerCase());
  });
  window.addEventListener("keyup", (e) => control.keys.delete(e.key.toLowerCase()));
  function orbitCamera(now) {
    if (!orbit) return null;
    const dt = control.last ? Math.min((now - control.last) / 1e3, 0.1) : 0;
    control.last = now;
    if (control.distance === 0) control.distance = orbit.radius * 1.5;
    if (control.auto) control.yaw += dt * (2 * Math.PI / 20);
    const dir = [
      -Math.cos(control.pitch) * Math.cos(control.yaw),
      -Math.sin(control.pitch),
      -Math.cos(control.pitch) * Math.sin(control.yaw)
    ];
    const speed = orbit.radius * 0.5 * dt;
    const k = control.keys;
    const fwd = (k.has("w") ? 1 : 0) - (k.has("s") ? 1 : 0);
    const side = (k.has("d") ? 1 : 0) - (k.has("a") ? 1 : 0);
    const lift = (k.has("e") ? 1 : 0) - (k.has("q") ? 1 : 0);
    if (fwd || side || lift) control.auto = false;
    const c = orbit.centre;
    const right = [-dir[2], 0, dir[0]];
    const rl = Math.hypot(right[0], right[2]) || 1;
    for (let i = 0; i < 3; i++) c[i] += speed * (fwd * dir[i] + side * right[i] / rl + (i === 1 ? lift : 0));
    const d = control.distance;
    return {
      frame: cameraFrame2,
      position: [c[0] - d * dir[0], c[1] - d * dir[1], c[2] - d * dir[2]],
      target: [c[0], c[1], c[2]],
      up: [0, 1, 0],
      fovY: Math.PI / 3,
      near: Math.max(d * 1e-3, 1e-3),
      far: (d + orbit.radius) * 4,
      aspect: canvas.width / Math.max(canvas.height, 1)
    };
  }
  function pathCamera(p, frame, index) {
    const f = p.frames[index % p.frames.length];
    return {
      frame,
      position: [f[0], f[1], f[2]],
      target: [f[3], f[4], f[5]],
      up: [f[6], f[7], f[8]],
      fovY: f[9],
      near: f[10],
      far: f[11],
      aspect: canvas.width / Math.max(canvas.height, 1)
    };
  }
  function currentCamera(now) {
    if (path && lockstep && testFrames !== null) {
      if (!session?.state) return { cam: null, send: false };
      if (answered === sent && sent < testFrames - 1) {
        sent++;
        return { cam: pathCamera(path, sent, sent), send: true };
      }
      return { cam: pathCamera(path, Math.max(answered, 0), Math.max(answered, 0)), send: false };
    }
    if (path && control.auto) {
      if (!pathStart) pathStart = now;
      pathFrame = Math.floor((now - pathStart) / 1e3 * 60);
      pathShown = pathCamera(path, cameraFrame2, pathFrame);
      return { cam: pathShown, send: true };
    }
    if (pathShown) {
      takeOverFrom(pathShown);
      pathShown = null;
    }
    return { cam: orbitCamera(now), send: true };
  }
  var pathShown = null;
  function takeOverFrom(cam) {
    if (!orbit) return;
    const look = [0, 1, 2].map((i) => cam.target[i] - cam.position[i]);
    const d = Math.hypot(look[0], look[1], look[2]) || 1;
    control.pitch = Math.max(-1.5, Math.min(1.5, Math.asin(Math.max(-1, Math.min(1, -look[1] / d)))));
    control.yaw = Math.atan2(-look[2], -look[0]);
    control.distance = d;
    orbit.centre = [cam.target[0], cam.target[1], cam.target[2]];
  }
  function measureCost() {
    const cam = status.camera;
    if (!gl || !renderer || !cam) return null;
    const time = sceneTime(performance.now());
    renderer.draw(cam, { mode: MODE_COST, state: session?.state ?? null, grids, scale, time });
    const w = gl.drawingBufferWidth;
    const h = gl.drawingBufferHeight;
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let covered = 0;
    let cells = 0;
    let points = 0;
    let maxCells = 0;
    let maxPoints = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (px[i + 3] !== 255) continue;
      covered++;
      const p = px[i + 1] + 256 * px[i + 2];
      cells += px[i];
      points += p;
      maxCells = Math.max(maxCells, px[i]);
      maxPoints = Math.max(maxPoints, p);
    }
    renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, time });
    return {
      width: w,
      height: h,
      covered,
      cellsPerPixel: covered ? cells / covered : 0,
      pointsPerPixel: covered ? points / covered : 0,
      maxCells,
      maxPoints
    };
  }
  window.psaoCost = measureCost;
  var lastCamera = 0;
  var lastPointCount = 0;
  var lastPing = 0;
  var cost = null;
  function ping(now) {
    if (now - lastPing < 2e3) return;
    lastPing = now;
    const t0 = performance.now();
    const edge = status.edge;
    fetch(`${location.protocol}//${edge}/health`, { cache: "no-store" }).then((r) => r.arrayBuffer()).then(() => {
      status.rttMs = performance.now() - t0;
      status.rttEdge = edge;
    }).catch(() => status.rttMs = null);
  }
  function tick(now) {
    frames.push(now);
    frames = frames.filter((t) => now - t < 1e3);
    received = received.filter((r) => now - r.t < 1e3);
    status.fps = frames.length;
    status.mbitS = received.reduce((a, r) => a + r.bytes, 0) * 8 / 1e6;
    const w0 = fixedRes ? Number(fixedRes[1]) : Math.round(window.innerWidth * devicePixelRatio);
    const h0 = fixedRes ? Number(fixedRes[2]) : Math.round(window.innerHeight * devicePixelRatio);
    if (canvas.width !== w0 || canvas.height !== h0) {
      canvas.width = w0;
      canvas.height = h0;
      if (fixedRes) {
        canvas.style.width = `${w0}px`;
        canvas.style.height = `${h0}px`;
      }
    }
    if (!lockstep) ping(now);
    const { cam, send } = currentCamera(now);
    status.camera = cam;
    status.autoOrbit = control.auto;
    status.path = path && (control.auto || lockstep) ? path.name : null;
    status.pathFrame = lockstep ? Math.max(answered, 0) : pathFrame;
    if (cam && send && (lockstep || now - lastCamera > 1e3 / 30)) {
      lastCamera = now;
      session?.sendCamera(cam);
      cameraFrame2++;
    }
    const drawNow = !(lockstep && testFrames !== null) || answered === testFrames - 1;
    if (cam && renderer && drawNow) {
      grids?.upload();
      renderer.draw(cam, { mode: status.mode, state: session?.state ?? null, grids, scale, time: sceneTime(now) });
      status.drawn++;
      if (status.milestones.ao === null && status.mode !== MODE_NO_AO && grids && grids.cellPages > 0 && !grids.problem) {
        status.milestones.ao = performance.now();
      }
      if (lockstep && testFrames !== null && answered === testFrames - 1) status.done = true;
    }
    if (now - lastPointCount > 500) {
      lastPointCount = now;
      status.points = countPoints();
    }
    status.decodeMs = session && session.updates > 0 ? session.decodeMs / session.updates : 0;
    status.uploadedBytes = grids?.uploadedBytes ?? 0;
    status.rebuilds = grids?.rebuilds ?? 0;
    status.textureBytes = grids ? grids.textureBytes() : 0;
    const w = session?.welcomeMsg;
    const modeName = ["composited", "AO only", "no AO"][status.mode] ?? "";
    overlay.textContent = [
      `psao viewer \u2014 ${status.connected ? `connected to ${status.edge}, scene ${w?.scene}, ${w?.instances.length} instances` : "not connected"}${edges.length > 1 ? ` (server ${edgeIndex + 1} of ${edges.length})` : ""}`,
      `${status.fps} fps \xB7 ${status.mbitS.toFixed(2)} Mbit/s \xB7 server frame ${status.serverFrame} \xB7 round trip ${status.rttMs === null ? "-" : `${status.rttMs.toFixed(1)} ms`}`,
      `${status.updates} updates \xB7 ${status.points} points received \xB7 ${status.decodeMs ? status.decodeMs.toFixed(2) : "-"} ms decode per update`,
      !renderer ? "WebGL2 unavailable: nothing drawn" : grids?.problem ? grids.problem : `view: ${modeName} (keys 1 2 3)${cost ? ` \xB7 AO shader ${cost.cellsPerPixel.toFixed(1)} cells, ${cost.pointsPerPixel.toFixed(1)} points per pixel (C)` : " \xB7 C: shader cost"}`,
      status.path ? `camera path ${status.path}, frame ${status.pathFrame} (drag, wheel or W A S D Q E to take over)` : `camera: ${path ? "yours" : "orbit"} (drag, wheel, W A S D Q E; Space: ${path ? "back to the path" : "auto"})`,
      verify ? `state hash ${status.hash ?? "-"}: ${status.verified} updates match the server, ${status.mismatches} differ` : "state hash not checked (add ?verify=1)"
    ].join("\n");
    message.textContent = status.message ? status.fatal ? `error: ${status.message}` : `${status.message}; reconnecting` : status.stalled ? `updates stalled: ${status.stalled}` : "";
    requestAnimationFrame(tick);
  }
  window.addEventListener("keydown", (e) => {
    if (e.key === "c") cost = measureCost();
  });
  fetch("/scene.glb", { headers: token === null ? {} : { Authorization: `Bearer ${token}` } }).then((r) => {
    if (r.status === 401) throw new Error("wrong or missing token (open the page with #token=\u2026)");
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    return r.arrayBuffer();
  }).then((b) => {
    const glb = new Uint8Array(b);
    orbit = sceneBounds(glb);
    if (gl) {
      renderer = new SceneRenderer(gl, glb);
      status.milestones.scene = performance.now();
      if (pathName !== null) {
        path = renderer.paths.find((p) => p.name === pathName) ?? null;
        if (!path) status.message = `the scene has no camera path named ${pathName}`;
      } else if (!orbitOnly) {
        path = renderer.paths[0] ?? null;
      }
    }
  }).catch((e) => {
    status.message = `cannot load /scene.glb: ${e}`;
  });
  connect();
  requestAnimationFrame(tick);
})();
