// Radiance RGBE (.hdr) reader: the page's port of vocabulary/environment_io.cpp ReadRadianceHdr,
// so that the page lights a pack with the floats prt-view reads from the same file.
// Format: Greg Ward, "Real Pixels" (Graphics Gems II, 1991): a text header ending in an empty
// line, a resolution line, then scanlines of 4-byte RGBE pixels, flat (with old-style (1,1,1,n)
// repeat runs) or "new" run-length encoded (2, 2, width>>8, width&255, each channel coded
// separately). Safe on hostile input: every read is bounds-checked; errors are thrown as Error
// with a message naming the file and the problem.

// RGBE component: (c + 0.5)·2^(e − 136), 0 when e = 0 (environment_io.cpp RgbeComponent).
const kExponent = new Float64Array(256);
for (let e = 1; e < 256; ++e) kExponent[e] = 2 ** (e - 136);

/**
 * Parses a Radiance .hdr file.
 * @param {ArrayBuffer} buffer the file's bytes
 * @param {string} name the file's name, for messages
 * @returns {{width: number, height: number, rgb: Float32Array}} linear RGB, rows from the top
 */
export function parseRadianceHdr(buffer, name) {
  const bytes = new Uint8Array(buffer);
  let pos = 0;
  const fail = (msg) => {
    throw new Error(`${name}: ${msg}`);
  };
  const line = () => {
    const end = bytes.indexOf(10, pos);
    if (end < 0) fail('truncated header');
    if (end - pos > 65536) fail('header line too long');
    const s = new TextDecoder('latin1').decode(bytes.subarray(pos, end));
    pos = end + 1;
    return s;
  };
  if (!line().startsWith('#?')) fail('not a Radiance file (no #? line)');
  for (;;) {
    const l = line();
    if (l === '' || l === '\r') break;
    if (l.startsWith('FORMAT=') && !l.slice(7).startsWith('32-bit_rle_rgbe'))
      fail(`unsupported Radiance FORMAT '${l.slice(7)}' (only 32-bit_rle_rgbe)`);
  }
  const res = line();
  const m = /^\s*([-+]Y)\s+(\d+)\s+([-+]X)\s+(\d+)\s*$/.exec(res);
  if (!m) fail(`unsupported resolution line '${res}' (expected -Y h +X w)`);
  const height = Number(m[2]);
  const width = Number(m[4]);
  if (height < 2 || width !== 2 * height)
    fail(`${width}×${height} is not a lat-long map (width = 2 × height, height ≥ 2)`);
  if (width * height > 64 * 1024 * 1024) fail(`${width}×${height} is too large`);
  const rgb = new Float32Array(width * height * 3);
  const scan = new Uint8Array(width * 4);
  const get = (where) => {
    if (pos >= bytes.length) fail(`truncated in ${where}`);
    return bytes[pos++];
  };
  for (let y = 0; y < height; ++y) {
    const where = `scanline ${y}`;
    const newRle = width >= 8 && width < 32768 && pos + 4 <= bytes.length &&
                   bytes[pos] === 2 && bytes[pos + 1] === 2 && (bytes[pos + 2] & 0x80) === 0;
    if (newRle) {
      pos += 2;
      const encW = (bytes[pos] << 8) | bytes[pos + 1];
      pos += 2;
      if (encW !== width)
        fail(`${where}: RLE width ${encW} does not match the image width ${width}`);
      for (let c = 0; c < 4; ++c) {
        let x = 0;
        while (x < width) {
          let count = get(where);
          if (count > 128) {
            count -= 128;
            if (count > width - x) fail(`${where}: RLE run overflows the scanline`);
            const v = get(where);
            for (let i = 0; i < count; ++i) scan[4 * x++ + c] = v;
          } else {
            if (count === 0 || count > width - x) fail(`${where}: bad RLE literal count ${count}`);
            if (pos + count > bytes.length) fail(`truncated in ${where}`);
            for (let i = 0; i < count; ++i) scan[4 * x++ + c] = bytes[pos++];
          }
        }
      }
    } else {
      let x = 0;
      let shift = 0;
      while (x < width) {
        if (pos + 4 > bytes.length) fail(`truncated in ${where}`);
        const p0 = bytes[pos], p1 = bytes[pos + 1], p2 = bytes[pos + 2], p3 = bytes[pos + 3];
        pos += 4;
        if (p0 === 1 && p1 === 1 && p2 === 1) {  // old-style run: repeat the previous pixel
          if (x === 0) fail(`${where}: repeat run with no previous pixel`);
          if (shift > 16) fail(`${where}: repeat run too long`);
          const count = p3 * 2 ** shift;
          if (count > width - x) fail(`${where}: repeat run overflows scanline`);
          for (let i = 0; i < count; ++i, ++x) scan.copyWithin(4 * x, 4 * (x - 1), 4 * x);
          shift += 8;
        } else {
          scan[4 * x] = p0;
          scan[4 * x + 1] = p1;
          scan[4 * x + 2] = p2;
          scan[4 * x + 3] = p3;
          ++x;
          shift = 0;
        }
      }
    }
    const row = m[1] === '-Y' ? y : height - 1 - y;
    for (let x = 0; x < width; ++x) {
      const col = m[3] === '+X' ? x : width - 1 - x;
      const f = kExponent[scan[4 * x + 3]];
      const o = 3 * (row * width + col);
      // Stored as float32, as the C++ reader stores (c + 0.5)·2^(e − 136) computed in double.
      rgb[o] = (scan[4 * x] + 0.5) * f;
      rgb[o + 1] = (scan[4 * x + 1] + 0.5) * f;
      rgb[o + 2] = (scan[4 * x + 2] + 0.5) * f;
    }
  }
  return {width, height, rgb};
}
