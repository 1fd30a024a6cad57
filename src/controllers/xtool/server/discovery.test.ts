import dgram from 'node:dgram';
import net from 'node:net';
import { afterEach, describe, expect, it } from 'vitest';
import { discoverXtool, parseReply } from './discovery';
import path from 'node:path';
import { startGateway, tempDir, consoleFetch, login, user, writeJson } from '../../../../gateway/test-util';
import { xtoolFamily } from '../family';
import { xtoolServer } from '.';

/**
 * A laser stand-in on 127.0.0.1: receives the broadcast on its UDP port, answers on TCP first,
 * then on UDP to the sender (protocol document, "Discovery"). Ports are free ones, never 20000.
 */

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

async function freePort(type: 'udp' | 'tcp'): Promise<number> {
  if (type === 'tcp') {
    const s = net.createServer();
    await new Promise<void>((r) => s.listen(0, '127.0.0.1', () => r()));
    const p = (s.address() as net.AddressInfo).port;
    await new Promise<void>((r) => s.close(() => r()));
    return p;
  }
  const s = dgram.createSocket('udp4');
  await new Promise<void>((r) => s.bind(0, '127.0.0.1', () => r()));
  const p = s.address().port;
  await new Promise<void>((r) => s.close(() => r()));
  return p;
}

async function fakeLaser(tcpPort: number): Promise<{ port: number; requests: string[] }> {
  const sock = dgram.createSocket('udp4');
  const requests: string[] = [];
  sock.on('message', (msg, rinfo) => {
    const text = msg.toString('utf8');
    requests.push(text);
    const { requestId } = JSON.parse(text) as { requestId: number };
    const reply = JSON.stringify({
      requestId,
      ip: '127.0.0.1',
      name: 'xTool D1 Pro',
      version: '40.31.006.01',
    });
    const c = net.connect(tcpPort, '127.0.0.1', () => c.end(reply));
    c.on('error', () => undefined);
    c.on('close', () => sock.send(reply, rinfo.port, rinfo.address));
    // An answer to someone else's request is ignored.
    sock.send(
      JSON.stringify({ requestId: requestId + 1, ip: '10.9.9.9', name: 'other', version: '1' }),
      rinfo.port,
      rinfo.address,
    );
  });
  await new Promise<void>((r) => sock.bind(0, '127.0.0.1', () => r()));
  cleanups.push(() => new Promise<void>((r) => sock.close(() => r())));
  return { port: sock.address().port, requests };
}

describe('xTool discovery', () => {
  it('parses replies leniently and ignores our own broadcast', () => {
    expect(
      parseReply('{"requestId":1,"ip":"1.2.3.4","name":"","version":"V40.32.013.2224.01"}', 'udp'),
    ).toEqual({
      requestId: 1,
      ip: '1.2.3.4',
      name: '',
      version: 'V40.32.013.2224.01',
      via: 'udp',
    });
    expect(parseReply('{"requestId":123456}', 'udp')).toBeNull();
    expect(parseReply('not json', 'tcp')).toBeNull();
  });

  it('broadcasts a request id and collects TCP and UDP answers', async () => {
    const tcpPort = await freePort('tcp');
    const listenUdpPort = await freePort('udp');
    const laser = await fakeLaser(tcpPort);
    const r = await discoverXtool({
      broadcast: '127.0.0.1',
      udpPort: laser.port,
      listenUdpPort,
      tcpPort,
      listenMs: 1000,
      bindAddress: '127.0.0.1',
    });
    expect(laser.requests).toEqual([JSON.stringify({ requestId: r.requestId })]);
    expect(r.replies.map((x) => [x.via, x.ip, x.name, x.requestId]).sort()).toEqual([
      ['tcp', '127.0.0.1', 'xTool D1 Pro', r.requestId],
      ['udp', '127.0.0.1', 'xTool D1 Pro', r.requestId],
    ]);
  });

  it('GET /api/discover/xtool answers { replies, broadcast }', async () => {
    const tcpPort = await freePort('tcp');
    const listenUdpPort = await freePort('udp');
    const laser = await fakeLaser(tcpPort);
    const t = tempDir();
    cleanups.push(t.cleanup);
    const gw = await startGateway({
      machines: { file: null, machines: [] },
      // The route is the xTool family's server part's (as src/controllers/families.ts lists it).
      families: { xtool: { ...xtoolFamily, server: xtoolServer } },
      dataDir: t.dir,
      env: { SHOPDECK_DISCOVERY_BROADCAST: '127.0.0.1' },
      discovery: { udpPort: laser.port, listenUdpPort, tcpPort, listenMs: 1000, bindAddress: '127.0.0.1' },
    });
    cleanups.push(gw.close);
    const body = (await (await consoleFetch(`${gw.url}/api/discover/xtool`)).json()) as {
      replies: Array<{ via: string }>;
      broadcast: string;
    };
    expect(body.broadcast).toBe('127.0.0.1');
    expect(body.replies.map((x) => x.via).sort()).toEqual(['tcp', 'udp']);
  });

  it('the route the family declares keeps its guard: no session 401, viewer and operator 403, other methods and families 404', async () => {
    const t = tempDir();
    cleanups.push(t.cleanup);
    const usersFile = writeJson(path.join(t.dir, 'users.json'), {
      users: [user('vera', 'viewer', 'viewer-pass-1'), user('otto', 'operator', 'operator-pass-1')],
    });
    const gw = await startGateway({
      machines: { file: null, machines: [] },
      families: { xtool: { ...xtoolFamily, server: xtoolServer } },
      dataDir: t.dir,
      usersFile,
      env: {},
      // Nothing answers here: a request that got past the guard would still end (and fail the test).
      discovery: { broadcast: '127.0.0.1', udpPort: 9, tcpPort: 0, listenMs: 50, bindAddress: '127.0.0.1' },
    });
    cleanups.push(gw.close);
    const url = `${gw.url}/api/discover/xtool`;
    expect((await consoleFetch(url)).status).toBe(401);
    for (const [name, pass] of [
      ['vera', 'viewer-pass-1'],
      ['otto', 'operator-pass-1'],
    ] as const) {
      const cookie = await login(gw.url, name, pass);
      const r = await consoleFetch(url, { headers: { cookie } });
      expect(r.status).toBe(403);
      expect(await r.json()).toEqual({
        error: 'finding lasers on the network is for supervisors',
        needs: 'supervisor',
      });
      const post = await consoleFetch(url, { method: 'POST', headers: { cookie } });
      expect(post.status).toBe(404);
      expect((await consoleFetch(`${gw.url}/api/discover/duet`, { headers: { cookie } })).status).toBe(404);
    }
  });
});
