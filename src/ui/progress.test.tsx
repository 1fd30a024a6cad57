// @vitest-environment happy-dom
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { ProgressBar } from './components';

afterEach(cleanup);

/** Issue 16: a progress bar moves with `transform` only, so no frame of it costs a layout. */
describe('ProgressBar', () => {
  it('scales its fill instead of resizing it', () => {
    render(<ProgressBar value={0.42} label="job" />);
    const bar = screen.getByRole('progressbar', { name: 'job' });
    expect(bar.getAttribute('aria-valuenow')).toBe('42');
    const fill = bar.querySelector('span');
    expect(fill?.style.transform).toBe('scaleX(0.42)');
    expect(fill?.style.width).toBe('');
  });

  it('an unknown value is indeterminate, with no inline size', () => {
    render(<ProgressBar value={null} label="job" />);
    const bar = screen.getByRole('progressbar', { name: 'job' });
    expect(bar.className).toContain('indeterminate');
    expect(bar.getAttribute('aria-valuenow')).toBeNull();
    expect(bar.querySelector('span')?.getAttribute('style')).toBeNull();
  });

  it('the stylesheet animates and transitions the bar with transform only, and not with reduced motion', () => {
    const css = readFileSync(path.join(import.meta.dirname, 'theme.css'), 'utf8');
    const keyframes = /@keyframes ui-indet \{([\s\S]*?)\n\}/.exec(css)?.[1] ?? '';
    expect(keyframes).toContain('transform');
    expect(keyframes).not.toMatch(/\b(left|right|width|margin|inset)\s*:/);
    for (const m of css.matchAll(/transition:\s*([^;]+);/g))
      expect(m[1]).not.toMatch(/\b(width|height|left|top)\b/);
    expect(css).toMatch(/prefers-reduced-motion: reduce\)\s*\{[\s\S]*?animation: none/);
  });
});
