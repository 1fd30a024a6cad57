// @vitest-environment happy-dom
import { cleanup, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it } from 'vitest';
import { matchRoute } from './router';

afterEach(() => {
  cleanup();
  history.replaceState(null, '', '/');
});

describe('issue 12 (6): a malformed percent-encoding in the URL', () => {
  it.each(['/m/%E0%A4%A', '/m/%', '/audit/%zz', '/%E0%A4%A/page', '/m/p1/%C0'])(
    'matchRoute(%j) is the not-found route, not an exception',
    (path) => {
      expect(matchRoute(path)).toEqual({ name: 'not-found' });
    },
  );

  it('still decodes well-formed escapes', () => {
    expect(matchRoute('/m/shop%20laser/files')).toEqual({ name: 'machine', id: 'shop laser', tab: 'files' });
    expect(matchRoute('/m/%E0%A4%A8')).toEqual({ name: 'machine', id: '\u0928', tab: null });
  });

  it('the console shows its not-found page, not a blank page', async () => {
    history.replaceState(null, '', '/m/%E0%A4%A');
    const { App } = await import('./App');
    render(<App />);
    expect(screen.getByText(/There is no page here/)).toBeTruthy();
    expect(screen.getByRole('link', { name: 'Back to the fleet' })).toBeTruthy();
  });
});
