import { describe, expect, it } from 'vitest';
import { BACKGROUND_COLOR, NEVER_CACHED, pwaOptions, THEME_COLOR } from './options';
import { readFileSync } from 'node:fs';
import path from 'node:path';

const denied = (p: string): boolean => NEVER_CACHED.some((r) => r.test(p));

describe('the service worker configuration', () => {
  it('never answers a navigation to the gateway, a controller, the health check or the CA with the shell', () => {
    for (const p of [
      '/api',
      '/api/machines',
      '/api/session',
      '/api/audit.csv?machine=laser-1',
      '/api?x=1',
      '/machines/laser-1/status',
      '/machines/plasma-1/rest/v1/screenshot',
      '/healthz',
      '/shopdeck-ca.crt',
      '/shopdeck-ca',
      '/shopdeck-ca?x=1',
    ])
      expect(denied(p), p).toBe(true);
  });

  it('answers the console’s own routes with the shell', () => {
    for (const p of [
      '/',
      '/m/laser-1',
      '/m/laser-1/files',
      '/audit',
      '/alarms',
      '/login',
      '/xtool/discover',
      '/apis',
      '/m/machines',
    ])
      expect(denied(p), p).toBe(false);
  });

  it('caches nothing at run time and precaches the whole app shell', () => {
    const w = pwaOptions.workbox;
    // No runtime route at all: machine data (/machines, /api) never lands in the worker's caches,
    // so nothing of it is left there after logout.
    expect(w?.runtimeCaching).toEqual([]);
    expect(w?.globPatterns?.some((g) => /machines|api/.test(g))).toBe(false);
    expect(w?.navigateFallback).toBe('index.html');
    expect(w?.navigateFallbackDenylist).toBe(NEVER_CACHED);
    // Every JS and CSS chunk (each family's code) and index.html.
    expect(w?.globPatterns).toEqual(['**/*.{js,css,html}']);
    expect(pwaOptions.devOptions?.enabled).toBe(false);
    expect(pwaOptions.registerType).toBe('autoUpdate');
    expect(w?.skipWaiting).toBe(true);
    expect(w?.clientsClaim).toBe(true);
  });

  it('uses the theme’s colours', () => {
    const css = readFileSync(path.resolve(import.meta.dirname, '../../ui/theme.css'), 'utf8');
    const light = (name: string): string | undefined =>
      new RegExp(`--${name}: light-dark\\((#[0-9a-f]{6}),`).exec(css)?.[1];
    expect(light('panel')).toBe(THEME_COLOR);
    expect(light('bg')).toBe(BACKGROUND_COLOR);
    const m = pwaOptions.manifest;
    expect(m && m.theme_color).toBe(THEME_COLOR);
    expect(m && m.background_color).toBe(BACKGROUND_COLOR);
  });
});
