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
  function emptyBucket() {
    return {
      lo: new Uint32Array(BUCKET_ENTRIES),
      hi: new Uint32Array(BUCKET_ENTRIES),
      slots: new Uint32Array(BUCKET_ENTRIES)
    };
  }
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
  function usedEntries(b) {
    let n = 0;
    while (n < BUCKET_ENTRIES && (b.lo[n] !== 0 || b.hi[n] !== 0)) n++;
    return n;
  }
  function usedPoints(points) {
    let n = 0;
    while (n < CELL_POINTS && points[n] !== 0) n++;
    return n;
  }
  function decodeCount(code, old, capacity, at, plane, what) {
    if (code > capacity) throw new DeltaError(`${what} ${code} exceeds ${capacity}`);
    const n = (code + old) % (capacity + 1);
    if (at + n > plane) throw new DeltaError(`byte planes hold ${plane} records, the index stream implies ${at + n}`);
    return n;
  }
  var EMPTY_BUCKET = emptyBucket();
  var EMPTY_CELL = new Uint32Array(CELL_POINTS);
  var CompactDecoder = class {
    /// Most decompressed bytes accepted per update (a client sets it from its instance table).
    constructor(limit = MAX_DECODED_BYTES) {
      this.limit = limit;
      this.transforms = /* @__PURE__ */ new Map();
      this.buckets = /* @__PURE__ */ new Map();
      this.cells = /* @__PURE__ */ new Map();
      this.limit = Math.min(limit, MAX_DECODE_LIMIT);
    }
    clear() {
      this.transforms.clear();
      this.buckets.clear();
      this.cells.clear();
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
        let received2 = this.buckets.get(instance);
        if (!received2) this.buckets.set(instance, received2 = /* @__PURE__ */ new Map());
        const buckets = [];
        for (const b of bucketIds) {
          const code = s.entryCounts[entryCount++];
          const old = received2.get(b) ?? EMPTY_BUCKET;
          const n = decodeCount(code, usedEntries(old), BUCKET_ENTRIES, entry, s.entryChoices.length, "bucket entry count");
          const bucket = emptyBucket();
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
              const o = (i + c) % BUCKET_ENTRIES;
              const rLo = old.lo[o];
              const rHi = old.hi[o];
              if (rLo !== 0 || rHi !== 0) {
                const mLo = rLo === 0 ? 4294967295 : rLo - 1;
                const mHi = rLo === 0 ? rHi - 1 : rHi;
                tLo = (tLo ^ mLo ^ b) >>> 0;
                tHi = (tHi ^ mHi) >>> 0;
              }
              slot = (sr ^ old.slots[o]) >>> 0;
            } else {
              throw new DeltaError("bad reference choice for a bucket entry");
            }
            const xLo = (tLo ^ b) >>> 0;
            if (xLo === 4294967295 && tHi === 4294967295) throw new DeltaError("bad bucket key");
            bucket.lo[i] = xLo === 4294967295 ? 0 : xLo + 1;
            bucket.hi[i] = xLo === 4294967295 ? tHi + 1 : tHi;
            bucket.slots[i] = slot;
          }
          received2.set(b, bucket);
          buckets.push([b, bucket]);
        }
        let receivedCells = this.cells.get(instance);
        if (!receivedCells) this.cells.set(instance, receivedCells = /* @__PURE__ */ new Map());
        const cells = [];
        let previous = EMPTY_CELL;
        for (const slot of slotIds) {
          const code = s.cellLengths[cellCount++];
          const old = receivedCells.get(slot) ?? EMPTY_CELL;
          const n = decodeCount(code, usedPoints(old), CELL_POINTS, point, s.pointChoices.length, "cell length");
          const cell = new Uint32Array(CELL_POINTS);
          for (let i = 0; i < n; i++) {
            const c = s.pointChoices[point];
            const residual = s.points[point];
            point++;
            if (c >= POINT_CHOICES) throw new DeltaError("bad reference choice for a point");
            if ((residual & VALID_BIT) !== 0) throw new DeltaError("bad point residual");
            const reference = c < CELL_POINTS ? old[(i + c) % CELL_POINTS] : previous[c - CELL_POINTS];
            cell[i] = applyPointResidual(residual, reference);
          }
          receivedCells.set(slot, cell);
          previous = cell;
          cells.push([slot, cell]);
        }
        instances.push({ instance, buckets, cells });
      }
      if (entry !== s.entryChoices.length || point !== s.pointChoices.length) {
        throw new DeltaError(`${s.entryChoices.length - entry + s.pointChoices.length - point} trailing records`);
      }
      return { frame, snapshot, transforms, instances };
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
      /// Cell slots in use (the length `points` covers).
      this.slotCount = 0;
      this.keyLo = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.keyHi = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.slots = new Uint32Array(entry.bucketCount * BUCKET_ENTRIES);
      this.points = new Uint32Array(0);
    }
    /// Most cell slots the layout allows.
    maxCells() {
      return this.entry.bucketCount * BUCKET_ENTRIES;
    }
    ensureSlot(slot) {
      if (slot < this.slotCount) return;
      this.slotCount = slot + 1;
      if (this.points.length < this.slotCount * CELL_POINTS) {
        const grown = new Uint32Array(Math.max(this.slotCount, 2 * (this.points.length / CELL_POINTS)) * CELL_POINTS);
        grown.set(this.points);
        this.points = grown;
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
      this.lastFrame = null;
      this.grids = table.map((e) => usable(e) ? new Grid(e) : null);
      this.transforms = table.map(() => null);
    }
    /// Applies a decoded update after checking all of it (nothing changes on an error).
    apply(u) {
      this.validate(u);
      if (u.snapshot) {
        for (let i = 0; i < this.grids.length; i++) {
          const g = this.grids[i];
          if (g) this.grids[i] = new Grid(g.entry);
        }
        this.transforms.fill(null);
      }
      for (const [instance, t] of u.transforms) this.transforms[instance] = t;
      for (const d of u.instances) {
        const g = this.grids[d.instance];
        for (const [b, bucket] of d.buckets) {
          const base = b * BUCKET_ENTRIES;
          for (let i = 0; i < BUCKET_ENTRIES; i++) {
            g.keyLo[base + i] = bucket.lo[i];
            g.keyHi[base + i] = bucket.hi[i];
            g.slots[base + i] = bucket.slots[i];
            if (bucket.lo[i] !== 0 || bucket.hi[i] !== 0) g.ensureSlot(bucket.slots[i]);
          }
        }
        for (const [slot, cell] of d.cells) {
          g.ensureSlot(slot);
          g.points.set(cell, slot * CELL_POINTS);
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
        for (const [b, bucket] of d.buckets) {
          if (b >= g.entry.bucketCount) throw new ApplyError(`instance ${d.instance}: bucket ${b} out of range`);
          for (let i = 0; i < BUCKET_ENTRIES; i++) {
            const lo = bucket.lo[i];
            const hi = bucket.hi[i];
            if (lo === 0 && hi === 0) continue;
            if (bucket.slots[i] >= max) throw new ApplyError(`instance ${d.instance}: cell slot ${bucket.slots[i]} out of range`);
            const idLo = lo === 0 ? 4294967295 : lo - 1;
            const idHi = lo === 0 ? hi - 1 : hi;
            if (!g.idIsValid(idHi, idLo) || (idLo & mask) >>> 0 !== b) {
              throw new ApplyError(`instance ${d.instance}: bucket ${b} has an invalid cell key`);
            }
          }
        }
        for (const [slot] of d.cells) {
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
      this.ws = new WebSocket(opts.url);
      this.ws.binaryType = "arraybuffer";
      this.ws.onopen = () => {
        const caps = CAP_CODEC_COMPACT | (opts.verify ? CAP_STATE_HASH : 0);
        this.ws.send(helloFrame({ version: PROTOCOL_VERSION, capabilities: caps, token: opts.token, name: opts.name }));
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
          this.decoder = new CompactDecoder(decodeLimit(w.instances));
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
          this.ws.send(ackFrame(m.delta.frame));
          this.handler.update(u, size, verified);
          if (m.delta.clientFrame !== null) this.handler.sceneTime?.(m.delta.frame, m.delta.clientFrame);
          return;
        }
        case "scene_time":
          this.handler.sceneTime?.(m.frame, m.clientFrame);
          return;
        case "error": {
          const fatal = m.code === "Token" || m.code === "Version";
          const text = m.code === "Token" ? `wrong or missing token: ${m.message}` : m.code === "Version" ? `protocol version mismatch: ${m.message}` : `server error (${m.code}): ${m.message}`;
          return this.fail(text, fatal);
        }
        case "bye":
          return this.end(`the server said bye: ${m.reason}`, false);
        default:
          return this.fail(`unexpected ${m.kind} from the server`, true);
      }
    }
    /// Sends the client's camera.
    sendCamera(c) {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.ws.send(cameraFrame(c));
    }
    /// Ends the session with a bye.
    close() {
      if (!this.done && this.ws.readyState === WebSocket.OPEN) this.ws.send(byeFrame("done"));
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

  // src/render.ts
  var VERTEX = `#version 300 es
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
uniform mat4 view_proj;
uniform mat4 model;
out vec3 world_normal;
void main() {
  world_normal = mat3(model) * normal;
  gl_Position = view_proj * model * vec4(position, 1.0);
}`;
  var FRAGMENT = `#version 300 es
precision highp float;
in vec3 world_normal;
uniform vec3 colour;
uniform vec3 light;
out vec4 out_colour;
void main() {
  float d = abs(dot(normalize(world_normal), light));
  out_colour = vec4(pow(colour * (0.25 + 0.75 * d), vec3(1.0 / 2.2)), 1.0);
}`;
  function compile(gl2, type, source) {
    const s = gl2.createShader(type);
    gl2.shaderSource(s, source);
    gl2.compileShader(s);
    if (!gl2.getShaderParameter(s, gl2.COMPILE_STATUS)) throw new Error(`shader: ${gl2.getShaderInfoLog(s)}`);
    return s;
  }
  var SceneRenderer = class {
    constructor(gl2, glb) {
      this.gl = gl2;
      this.meshes = [];
      this.instances = [];
      const p = gl2.createProgram();
      gl2.attachShader(p, compile(gl2, gl2.VERTEX_SHADER, VERTEX));
      gl2.attachShader(p, compile(gl2, gl2.FRAGMENT_SHADER, FRAGMENT));
      gl2.linkProgram(p);
      if (!gl2.getProgramParameter(p, gl2.LINK_STATUS)) throw new Error(`program: ${gl2.getProgramInfoLog(p)}`);
      this.program = p;
      this.uViewProj = gl2.getUniformLocation(p, "view_proj");
      this.uModel = gl2.getUniformLocation(p, "model");
      this.uColour = gl2.getUniformLocation(p, "colour");
      this.uLight = gl2.getUniformLocation(p, "light");
      this.load(glb);
    }
    load(glb) {
      const gl2 = this.gl;
      const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
      const jsonLen = view.getUint32(12, true);
      const doc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
      const binAt = 20 + jsonLen + 8;
      const bin = glb.subarray(binAt, binAt + view.getUint32(20 + jsonLen, true));
      const data = (index) => {
        const a = doc.accessors[index];
        const bv = doc.bufferViews[a.bufferView];
        const width = { SCALAR: 1, VEC3: 3, VEC4: 4 }[a.type] ?? 1;
        const start = (bv.byteOffset ?? 0) + (a.byteOffset ?? 0);
        return { bytes: bin.subarray(start, start + a.count * width * 4), count: a.count };
      };
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
          const idx = data(prim.indices);
          const ibo = gl2.createBuffer();
          gl2.bindBuffer(gl2.ELEMENT_ARRAY_BUFFER, ibo);
          gl2.bufferData(gl2.ELEMENT_ARRAY_BUFFER, idx.bytes, gl2.STATIC_DRAW);
          gl2.bindVertexArray(null);
          const c = doc.materials?.[prim.material ?? 0]?.pbrMetallicRoughness?.baseColorFactor ?? [0.8, 0.8, 0.8, 1];
          prims.push({ vao, count: idx.count, colour: [c[0], c[1], c[2]] });
        }
        this.meshes.push(prims);
      }
      for (const node of doc.nodes ?? []) {
        if (node.mesh === void 0 || !node.matrix) break;
        this.instances.push({ mesh: node.mesh, matrix: new Float32Array(node.matrix) });
      }
    }
    /// Draws the scene from `camera`; `transforms[i]`, when set, is instance i's Affine3A from
    /// the last update (12 floats: matrix columns, then translation).
    draw(camera, transforms) {
      const gl2 = this.gl;
      gl2.viewport(0, 0, gl2.drawingBufferWidth, gl2.drawingBufferHeight);
      gl2.clearColor(0.07, 0.07, 0.07, 1);
      gl2.clear(gl2.COLOR_BUFFER_BIT | gl2.DEPTH_BUFFER_BIT);
      gl2.enable(gl2.DEPTH_TEST);
      gl2.useProgram(this.program);
      gl2.uniformMatrix4fv(this.uViewProj, false, viewProj(camera));
      const [px, py, pz] = camera.position;
      const [tx, ty, tz] = camera.target;
      const l = Math.hypot(tx - px, ty - py, tz - pz) || 1;
      gl2.uniform3f(this.uLight, (tx - px) / l, (ty - py) / l, (tz - pz) / l);
      const model = new Float32Array(16);
      for (const [i, inst] of this.instances.entries()) {
        const t = transforms[i];
        if (t) {
          model.set([t[0], t[1], t[2], 0, t[3], t[4], t[5], 0, t[6], t[7], t[8], 0, t[9], t[10], t[11], 1]);
        } else {
          model.set(inst.matrix);
        }
        gl2.uniformMatrix4fv(this.uModel, false, model);
        for (const p of this.meshes[inst.mesh] ?? []) {
          gl2.uniform3f(this.uColour, p.colour[0], p.colour[1], p.colour[2]);
          gl2.bindVertexArray(p.vao);
          gl2.drawElements(gl2.TRIANGLES, p.count, gl2.UNSIGNED_INT, 0);
        }
      }
      gl2.bindVertexArray(null);
    }
  };
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
    mbitS: 0,
    fps: 0,
    drawn: 0,
    camera: null,
    autoOrbit: true
  };
  window.psao = status;
  var params = new URLSearchParams(location.search);
  var token = params.get("token");
  var verify = params.get("verify") === "1";
  var wsUrl = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`;
  var session = null;
  var backoff = 200;
  var received = [];
  function connect() {
    session = new Session(
      { url: wsUrl, token, verify, name: "psao browser viewer" },
      {
        welcome: () => {
          status.connected = true;
          status.sessions++;
          status.message = null;
          backoff = 200;
        },
        update: (u, bytes, verified) => {
          status.updates++;
          if (verified) status.verified++;
          status.mismatches = session?.mismatches ?? status.mismatches;
          status.serverFrame = Number(u.frame);
          received.push({ t: performance.now(), bytes });
          if (session?.lastHash != null) status.hash = session.lastHash.toString(16).padStart(16, "0");
        },
        closed: (reason, fatal) => {
          status.connected = false;
          status.message = reason;
          status.fatal = fatal;
          if (!fatal) {
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
  var gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true });
  var renderer = null;
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
    if (e.key === " ") control.auto = true;
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
  var lastCamera = 0;
  var lastPointCount = 0;
  function tick(now) {
    frames.push(now);
    frames = frames.filter((t) => now - t < 1e3);
    received = received.filter((r) => now - r.t < 1e3);
    status.fps = frames.length;
    status.mbitS = received.reduce((a, r) => a + r.bytes, 0) * 8 / 1e6;
    const w0 = Math.round(window.innerWidth * devicePixelRatio);
    const h0 = Math.round(window.innerHeight * devicePixelRatio);
    if (canvas.width !== w0 || canvas.height !== h0) {
      canvas.width = w0;
      canvas.height = h0;
    }
    const cam = orbitCamera(now);
    status.camera = cam;
    status.autoOrbit = control.auto;
    if (cam && now - lastCamera > 1e3 / 30) {
      lastCamera = now;
      session?.sendCamera(cam);
      cameraFrame2++;
    }
    if (cam && renderer) {
      renderer.draw(cam, session?.state?.transforms ?? []);
      status.drawn++;
    }
    if (now - lastPointCount > 500) {
      lastPointCount = now;
      status.points = countPoints();
    }
    const w = session?.welcomeMsg;
    overlay.textContent = [
      `psao viewer \u2014 ${status.connected ? `connected, scene ${w?.scene}, ${w?.instances.length} instances` : "not connected"}`,
      `${status.fps} fps \xB7 ${status.mbitS.toFixed(2)} Mbit/s \xB7 server frame ${status.serverFrame}`,
      `${status.updates} updates \xB7 ${status.points} points received \xB7 ${session && session.updates > 0 ? (session.decodeMs / session.updates).toFixed(2) : "-"} ms decode per update`,
      renderer ? "WebGL2: the scene without AO (the AO shader is not here yet)" : "WebGL2 unavailable: nothing drawn",
      verify ? `state hash ${status.hash ?? "-"}: ${status.verified} updates match the server, ${status.mismatches} differ` : "state hash not checked (add ?verify=1)"
    ].join("\n");
    message.textContent = status.message ? status.fatal ? `error: ${status.message}` : `${status.message}; reconnecting` : "";
    requestAnimationFrame(tick);
  }
  fetch("/scene.glb").then((r) => r.arrayBuffer()).then((b) => {
    const glb = new Uint8Array(b);
    orbit = sceneBounds(glb);
    if (gl) renderer = new SceneRenderer(gl, glb);
  }).catch((e) => {
    status.message = `cannot load /scene.glb: ${e}`;
  });
  connect();
  requestAnimationFrame(tick);
})();
