import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import { decodeEnum, httpStatusFor, statLabel, statusText } from './codes';

const table = JSON.parse(
  readFileSync(join(process.cwd(), 'tests/fixtures/g2core/status-codes.json'), 'utf8'),
) as {
  codes: { code: number; name: string; msg: string; range: string }[];
};

const range = (a: number, b: number) => Array.from({ length: b - a + 1 }, (_, i) => a + i);

/** The lists of "Commonly Used HTTP Response Codes" in g2core-rest-design.txt, typed in again. */
const DESIGN: Record<number, number[]> = {
  400: [
    ...range(101, 103),
    ...range(111, 116),
    ...range(200, 203),
    ...range(207, 209),
    ...range(130, 181),
    ...range(240, 247),
    ...range(250, 254),
  ],
  404: [100, 11],
  405: [104, 105, 106, ...range(220, 233)],
  410: [5, 6, 18, 204, 205, 206],
  413: [10, 107],
  416: [108, 109, 110],
  500: [...range(7, 9), ...range(12, 17), ...range(19, 36), ...range(88, 99)],
};

describe('status code → HTTP status', () => {
  it('matches every code the design lists', () => {
    let n = 0;
    for (const [http, codes] of Object.entries(DESIGN)) {
      for (const c of codes) {
        expect([c, httpStatusFor(c)]).toEqual([c, Number(http)]);
        n++;
      }
    }
    expect(n).toBeGreaterThan(100);
  });

  it('gives every code of the firmware table an HTTP status of its range', () => {
    const byRange: Record<string, number[]> = {
      ok: [200],
      'os/internal': [200, 404, 410, 413, 500],
      'internal error': [500],
      'input/json error': [400, 404, 405, 413, 416],
      'gcode error': [400],
      'machine/runtime error': [400, 410],
      'soft limit': [405],
      homing: [400],
      probe: [400],
    };
    expect(table.codes).toHaveLength(256);
    for (const c of table.codes) {
      expect(byRange[c.range], c.range).toBeDefined();
      expect(byRange[c.range]).toContain(httpStatusFor(c.code));
    }
  });

  it('uses the firmware text of the table', () => {
    for (const c of table.codes) {
      if (c.msg !== String(c.code)) expect(statusText(c.code)).toBe(c.msg);
      else expect(statusText(c.code)).toContain(c.name);
    }
    expect(statusText(104)).toBe('Parameter is read-only');
    expect(statusText(9999)).toBe('Status 9999');
  });
});

describe('state words', () => {
  it('stat 0..13 and unknown values', () => {
    expect(statLabel(0)).toBe('Initializing');
    expect(statLabel(6)).toBe('Hold');
    expect(statLabel(13)).toBe('Panic');
    expect(statLabel(42)).toBe('Unknown (raw 42)');
  });
  it('modal fields from the firmware enums', () => {
    expect(decodeEnum('unit', 0)).toBe('G20 inches');
    expect(decodeEnum('coor', 1)).toBe('G54');
    expect(decodeEnum('frmo', 1)).toBe('G94 units per minute');
    expect(decodeEnum('path', 2)).toBe('G64 continuous');
    expect(decodeEnum('momo', 99)).toBe('unknown (raw 99)');
  });
});
