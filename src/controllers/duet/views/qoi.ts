/**
 * A QOI ("Quite OK Image") decoder: slicers embed QOI thumbnails (`; thumbnail_QOI begin`) and
 * browsers cannot show them, so they are decoded to RGBA here and drawn on a canvas.
 * Spec: https://qoiformat.org/qoi-specification.pdf
 */
export interface DecodedImage {
  width: number;
  height: number;
  /** RGBA, 4 bytes per pixel */
  data: Uint8ClampedArray;
}

export function decodeQoi(bytes: Uint8Array): DecodedImage {
  if (bytes.length < 22 || bytes[0] !== 0x71 || bytes[1] !== 0x6f || bytes[2] !== 0x69 || bytes[3] !== 0x66) {
    throw new Error('not a QOI image');
  }
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const width = view.getUint32(4);
  const height = view.getUint32(8);
  if (!width || !height || width * height > 4096 * 4096) throw new Error('QOI: bad size');
  const out = new Uint8ClampedArray(width * height * 4);
  const index = new Uint8Array(64 * 4);
  let r = 0;
  let g = 0;
  let b = 0;
  let a = 255;
  let p = 14;
  let run = 0;
  const end = bytes.length - 8;
  for (let px = 0; px < out.length; px += 4) {
    if (run > 0) {
      run--;
    } else if (p < end) {
      const b1 = bytes[p++] ?? 0;
      if (b1 === 0xfe) {
        r = bytes[p++] ?? 0;
        g = bytes[p++] ?? 0;
        b = bytes[p++] ?? 0;
      } else if (b1 === 0xff) {
        r = bytes[p++] ?? 0;
        g = bytes[p++] ?? 0;
        b = bytes[p++] ?? 0;
        a = bytes[p++] ?? 0;
      } else if ((b1 & 0xc0) === 0x00) {
        const i = b1 * 4;
        r = index[i] ?? 0;
        g = index[i + 1] ?? 0;
        b = index[i + 2] ?? 0;
        a = index[i + 3] ?? 0;
      } else if ((b1 & 0xc0) === 0x40) {
        r = (r + ((b1 >> 4) & 0x03) - 2) & 0xff;
        g = (g + ((b1 >> 2) & 0x03) - 2) & 0xff;
        b = (b + (b1 & 0x03) - 2) & 0xff;
      } else if ((b1 & 0xc0) === 0x80) {
        const b2 = bytes[p++] ?? 0;
        const vg = (b1 & 0x3f) - 32;
        r = (r + vg - 8 + ((b2 >> 4) & 0x0f)) & 0xff;
        g = (g + vg) & 0xff;
        b = (b + vg - 8 + (b2 & 0x0f)) & 0xff;
      } else {
        run = b1 & 0x3f;
      }
      const h = ((r * 3 + g * 5 + b * 7 + a * 11) % 64) * 4;
      index[h] = r;
      index[h + 1] = g;
      index[h + 2] = b;
      index[h + 3] = a;
    }
    out[px] = r;
    out[px + 1] = g;
    out[px + 2] = b;
    out[px + 3] = a;
  }
  return { width, height, data: out };
}

export function base64ToBytes(b64: string): Uint8Array {
  const bin = atob(b64.replace(/\s+/g, ''));
  const out = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
  return out;
}
