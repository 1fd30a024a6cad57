import { describe, expect, it } from 'vitest';
import { matchRoute } from '../router';

describe('the History route', () => {
  it('/history is the history page', () => {
    expect(matchRoute('/history')).toEqual({ name: 'history' });
    expect(matchRoute('/history/')).toEqual({ name: 'history' });
  });
});
