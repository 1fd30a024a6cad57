import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, expect, it } from 'vitest';
import { groupKind, groupTitle, keyMeta, parseInput } from './settings-meta';

const tree = JSON.parse(
  readFileSync(join(process.cwd(), 'tests/fixtures/g2core/responses/config-groups-100.12.json'), 'utf8'),
) as Record<string, Record<string, unknown>>;

describe('settings metadata', () => {
  it('names every key of the 100.12 tree and every group', () => {
    const missing: string[] = [];
    for (const [g, keys] of Object.entries(tree)) {
      expect(groupKind(g)).not.toBe('other');
      expect(groupTitle(g)).not.toBe(g);
      for (const k of Object.keys(keys)) if (!keyMeta(g, k)) missing.push(`${g}.${k}`);
    }
    expect(missing).toEqual([]);
  });

  it('marks identity keys read-only and parses inputs by type', () => {
    expect(keyMeta('sys', 'fb')?.readOnly).toBe(true);
    expect(keyMeta('x', 'vm')?.readOnly).toBeFalsy();
    expect(parseInput(keyMeta('x', 'vm'), 40000, '30000')).toEqual({ value: 30000 });
    expect(parseInput(keyMeta('x', 'vm'), 40000, 'fast')).toEqual({ error: 'Enter a number' });
    expect(parseInput(keyMeta('1', 'pl'), 0.4, '1.5')).toEqual({ error: 'At most 1' });
    expect(parseInput(keyMeta('x', 'am'), 1, '1.5')).toEqual({ error: 'Enter a whole number' });
    expect(parseInput(keyMeta('he1', 'e'), false, 'true')).toEqual({ value: true });
    expect(parseInput(null, 'abc', 'xyz')).toEqual({ value: 'xyz' });
  });
});
