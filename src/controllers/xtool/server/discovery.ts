import dgram from 'node:dgram';
import net from 'node:net';
import { z } from 'zod';
import type { DiscoveryOptions } from '../../../fleet/server-part';

/**
 * xTool discovery (protocol document, "Discovery"): broadcast `{"requestId":n}` to UDP 20000;
 * a laser first tries to answer on TCP 20001, then the same JSON on UDP 20000. We listen on
 * both for `listenMs` and collect the answers that carry our request id.
 */

export type { DiscoveryOptions };

export interface DiscoveryReply {
  name: string;
  ip: string;
  version: string;
  requestId: number | null;
  via: 'udp' | 'tcp';
}

export interface DiscoveryResult {
  replies: DiscoveryReply[];
  broadcast: string;
  requestId: number;
  /** Listeners that could not be opened (port in use…): discovery still ran without them. */
  warnings: string[];
}

const replySchema = z.looseObject({
  requestId: z.coerce.number().optional(),
  ip: z.string(),
  name: z.coerce.string().optional(),
  version: z.coerce.string().optional(),
});

export function parseReply(text: string, via: 'udp' | 'tcp'): DiscoveryReply | null {
  let data: unknown;
  try {
    data = JSON.parse(text) as unknown;
  } catch {
    return null;
  }
  const r = replySchema.safeParse(data);
  // Our own broadcast comes back to us on UDP: it has no ip/version, so it fails here.
  if (!r.success || (r.data.version === undefined && r.data.name === undefined)) return null;
  return {
    name: r.data.name ?? '',
    ip: r.data.ip,
    version: r.data.version ?? '',
    requestId: r.data.requestId ?? null,
    via,
  };
}

export async function discoverXtool(o: DiscoveryOptions): Promise<DiscoveryResult> {
  const requestId = 1 + Math.floor(Math.random() * 999_999);
  const replies: DiscoveryReply[] = [];
  const warnings: string[] = [];
  const add = (r: DiscoveryReply | null): void => {
    if (!r || (r.requestId !== null && r.requestId !== requestId)) return;
    if (replies.some((x) => x.ip === r.ip && x.via === r.via)) return;
    replies.push(r);
  };

  const tcp = net.createServer((conn) => {
    const chunks: Buffer[] = [];
    let size = 0;
    conn.setTimeout(o.listenMs);
    conn.on('data', (c: Buffer) => {
      size += c.length;
      if (size > 64 * 1024) conn.destroy();
      else chunks.push(c);
    });
    conn.on('timeout', () => conn.destroy());
    conn.on('error', () => conn.destroy());
    conn.on('end', () => {
      add(parseReply(Buffer.concat(chunks).toString('utf8'), 'tcp'));
      conn.end();
    });
  });
  const tcpOk = await new Promise<boolean>((resolve) => {
    tcp.once('error', (e) => {
      warnings.push(`TCP ${o.tcpPort}: ${e.message}`);
      resolve(false);
    });
    tcp.listen(o.tcpPort, o.bindAddress, () => resolve(true));
  });

  const udp = dgram.createSocket({ type: 'udp4', reuseAddr: true });
  udp.on('message', (msg) => add(parseReply(msg.toString('utf8'), 'udp')));
  const listenPort = o.listenUdpPort ?? o.udpPort;
  const udpOk = await new Promise<boolean>((resolve) => {
    udp.once('error', (e) => {
      warnings.push(`UDP ${listenPort}: ${e.message}`);
      resolve(false);
    });
    udp.bind(listenPort, o.bindAddress, () => resolve(true));
  });
  let sock = udp;
  if (!udpOk) {
    // Fall back to any port: lasers that answer to the sender's port still reach us.
    udp.close();
    sock = dgram.createSocket({ type: 'udp4' });
    sock.on('message', (msg) => add(parseReply(msg.toString('utf8'), 'udp')));
    await new Promise<void>((resolve) => sock.bind(0, o.bindAddress, () => resolve()));
  }
  try {
    sock.setBroadcast(true);
    await new Promise<void>((resolve) => {
      sock.send(JSON.stringify({ requestId }), o.udpPort, o.broadcast, (err) => {
        if (err) warnings.push(`broadcast to ${o.broadcast}:${o.udpPort}: ${err.message}`);
        resolve();
      });
    });
    await new Promise((r) => setTimeout(r, o.listenMs));
  } finally {
    sock.close();
    if (tcpOk) await new Promise<void>((r) => tcp.close(() => r()));
  }
  return { replies, broadcast: o.broadcast, requestId, warnings };
}
