import { describe, expect, it } from 'vitest';
import { THUMB_QOI } from '../sim/data/thumbnails';
import { base64ToBytes, decodeQoi } from './qoi';

describe('decodeQoi', () => {
  it('decodes the simulator thumbnail: background corners, yellow triangle in the middle', () => {
    const img = decodeQoi(base64ToBytes(THUMB_QOI));
    expect([img.width, img.height]).toEqual([48, 48]);
    const px = (x: number, y: number) => Array.from(img.data.slice((y * 48 + x) * 4, (y * 48 + x) * 4 + 4));
    expect(px(0, 0)).toEqual([38, 70, 83, 255]);
    expect(px(24, 30)).toEqual([233, 196, 106, 255]);
    expect(px(47, 47)).toEqual([38, 70, 83, 255]);
  });
  it('refuses what is not QOI', () => {
    expect(() => decodeQoi(new Uint8Array(30))).toThrow(/QOI/);
  });
});
