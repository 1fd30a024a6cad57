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

  it('the stylesheet neither animates nor transitions anything: an idle page paints only when its data changes', () => {
    const css = readFileSync(path.join(import.meta.dirname, 'theme.css'), 'utf8');
    // An endless sweep (the indeterminate bar had one) or a transition run on every answer keeps
    // the renderer painting frames on a page where nothing but numbers changes.
    expect(css).not.toMatch(/@keyframes|\banimation(-name)?\s*:|\btransition(-property)?\s*:/);
    // The unknown-progress bar is told apart by its look (hatched), not by motion.
    expect(css).toMatch(/\.ui-progress\.indeterminate > span \{[^}]*repeating-linear-gradient/);
  });
});
