import { describe, expect, it } from 'vitest';
import { OVERRIDE_PHRASES, overrideLine, percent } from './phrases';

describe('g2core phrases: overrides as people read them', () => {
  it('says a factor in per cent, and an override turned off without its token', () => {
    expect(percent(0.85)).toBe('85 %');
    expect(overrideLine(OVERRIDE_PHRASES.mfo, 1.2, true)).toBe('Feed override: 120 %');
    expect(overrideLine(OVERRIDE_PHRASES.mfo, 1, false)).toBe(
      'Feed override: off — the machine runs at 100 %',
    );
    expect(overrideLine(OVERRIDE_PHRASES.sso, 0.5, false)).toBe(
      'Spindle override: off — the machine runs at 100 % (the 50 % set is kept)',
    );
    for (const p of Object.values(OVERRIDE_PHRASES))
      expect(overrideLine(p, 1, false)).not.toMatch(/[a-z]{2,}e ?=/);
  });
});
