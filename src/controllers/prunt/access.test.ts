import { describe, expect, it } from 'vitest';
import { pruntAccess } from './access';

const req = (method: string, path: string, websocket = false) =>
  pruntAccess({ method, path, query: new URLSearchParams(), websocket });

describe('pruntAccess', () => {
  it('reads and the live socket are for viewers', () => {
    for (const p of [
      '/config/schema',
      '/status/values',
      '/uploads/',
      '/uploads/a.gcode',
      '/update-check',
      '/update_check',
      '/extras/images/stepper_1.png',
    ]) {
      expect(req('GET', p)).toMatchObject({ role: 'viewer', command: false });
    }
    expect(req('GET', '/websocket/everything', true).role).toBe('viewer');
    // Reading the config writes nothing on the controller (Get_Values): a read, not audited.
    expect(req('GET', '/config/values')).toMatchObject({ role: 'viewer', command: false });
  });
  it('job controls and uploads are for operators, and audited', () => {
    for (const p of ['/pause/pause', '/pause/resume', '/cancel', '/run-file'])
      expect(req('POST', p)).toMatchObject({ role: 'operator', command: true });
    expect(req('PUT', '/uploads/part.gcode')).toMatchObject({ role: 'operator', command: true });
  });
  it('config, console, reload, firmware and anything unknown are for supervisors', () => {
    for (const p of [
      '/config/values',
      '/run-command',
      '/reload-server',
      '/allow-firmware-update',
      '/smart-plug/on',
      '/whatever',
    ]) {
      expect(req('POST', p)).toMatchObject({ role: 'supervisor', command: true });
    }
    expect(req('DELETE', '/uploads/a.gcode').role).toBe('supervisor');
  });
  it('matches the commands the session declares', async () => {
    const { PruntSession } = await import('./session');
    const { createContext } = await import('../../fleet/fleet');
    const { memoryDraftStorage } = await import('../../forms/storage');
    const s = new PruntSession(createContext({ id: 'p', name: 'p', kind: 'prunt', simulated: true }), {
      drafts: memoryDraftStorage(),
    });
    const paths: Record<string, [string, string]> = {
      'prunt.pause': ['POST', '/pause/pause'],
      'prunt.resume': ['POST', '/pause/resume'],
      'prunt.cancel': ['POST', '/cancel'],
      'prunt.runFile': ['POST', '/run-file'],
      'prunt.runCommand': ['POST', '/run-command'],
      'prunt.saveConfig': ['POST', '/config/values'],
      'prunt.reloadServer': ['POST', '/reload-server'],
      'prunt.allowFirmwareUpdate': ['POST', '/allow-firmware-update'],
      'prunt.upload': ['PUT', '/uploads/x.gcode'],
    };
    for (const c of Object.values(s.cmd)) {
      const [m, p] = paths[c.id] ?? ['?', '?'];
      expect(req(m, p).role, c.id).toBe(c.role);
    }
  });
});
