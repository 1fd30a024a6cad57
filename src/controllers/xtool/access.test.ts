import { describe, expect, it } from 'vitest';
import type { AccessDecision } from '../../fleet/access';
import { xtoolAccess } from './access';

function decide(method: string, pathWithQuery: string, websocket = false): AccessDecision {
  const [path = '/', qs = ''] = pathWithQuery.split('?');
  return xtoolAccess({ method, path, query: new URLSearchParams(qs), websocket });
}

describe('xtoolAccess', () => {
  it('reads are for viewers and not audited', () => {
    for (const p of [
      '/ping',
      '/progress',
      '/getmachinetype',
      '/getlaserpowertype',
      '/getlaserpowerinfo',
      '/peripherystatus',
      '/list?dir=/',
      '/system?action=get_working_sta',
      '/system?action=version',
      '/system?action=mac',
      '/system?action=offset',
      '/system?action=dotMode',
      '/system?action=get_dev_name',
    ]) {
      expect(decide('GET', p), p).toMatchObject({ role: 'viewer', command: false });
    }
    expect(decide('GET', '/', true)).toMatchObject({ role: 'viewer', command: false });
  });

  it('job controls and uploads are operator commands, even as GETs', () => {
    for (const a of ['pause', 'resume', 'stop']) {
      expect(decide('GET', `/cnc/data?action=${a}`)).toMatchObject({ role: 'operator', command: true });
    }
    expect(decide('POST', '/upload?filetype=1')).toMatchObject({ role: 'operator', command: true });
    expect(decide('POST', '/cnc/data?filetype=0')).toMatchObject({ role: 'operator', command: true });
  });

  it('settings, G-code, remote start, delete, firmware are supervisor commands', () => {
    for (const [m, p] of [
      ['GET', '/system?action=setTiltStopSwitch&tiltStopSwitch=0'],
      ['GET', '/system?action=setFlameAlarmSensitivity&flameAlarmSensitivity=3'],
      ['GET', '/system?action=set_dev_name&name=x'],
      ['GET', '/cmd?cmd=M28'],
      ['POST', '/cmd'],
      ['GET', '/read?file=/tmp.gcode'],
      ['GET', '/delete?file=/tmp.gcode'],
      ['POST', '/upgrade'],
      ['POST', '/net?action=connsta'],
    ] as const) {
      expect(decide(m, p), `${m} ${p}`).toMatchObject({ role: 'supervisor', command: true });
    }
  });

  it('unknown requests are supervisor-only commands, GET or not', () => {
    expect(decide('GET', '/framing')).toMatchObject({ role: 'supervisor', command: true });
    expect(decide('GET', '/system?action=reboot')).toMatchObject({ role: 'supervisor', command: true });
    expect(decide('GET', '/cnc/data?action=start')).toMatchObject({ role: 'supervisor', command: true });
    expect(decide('DELETE', '/progress')).toMatchObject({ role: 'supervisor', command: true });
  });
});
