import path from 'node:path';
import type { MachinesConfig } from '../gateway/machines';
import { CA_PAGE_PATH } from './ca-page';
import type { HealthReport } from './health';
import type { Logger } from './log';
import type { TlsMaterial } from './tls-cert';

/** What the server prints when it listens: for people (text), and the same as fields (JSON logs). */

export interface StartInfo {
  urls: string[];
  port: number;
  redirectPort: number | null;
}

export function logBanner(
  log: Logger,
  info: StartInfo,
  o: {
    distDir: string;
    dataDir: string;
    machines: MachinesConfig;
    users: HealthReport['users'];
    openOnNetwork: boolean;
    tls: TlsMaterial | null;
    tlsNotes: readonly string[];
  },
): void {
  const { users, machines, tls, tlsNotes, distDir, dataDir, openOnNetwork } = o;
  const usersText =
    users.mode === 'open'
      ? `open mode (no users file at ${users.file}): anyone who reaches the console controls every machine` +
        (openOnNetwork ? ' — and it listens on the network (SHOPDECK_OPEN=1)' : '')
      : users.loaded
        ? `${users.count} from ${users.file}`
        : `${users.file}: ${users.error}`;
  const machinesText = `${machines.machines.length} from ${machines.file ?? 'the built-in demo fleet (no machines file)'}`;
  // The URL to open comes last (after the details), where a newcomer's eye lands.
  const lines = [`Shopdeck is serving ${distDir}`, `  machines: ${machinesText}`, `  users:    ${usersText}`];
  if (tls) {
    lines.push(
      `  HTTPS:    certificate SHA-256 ${tls.fingerprint}` +
        (tls.source === 'files'
          ? ` (${tls.certFile})`
          : ` (self-signed, kept in ${path.dirname(tls.certFile)})`),
    );
    if (tls.ca)
      lines.push(
        `            tablets: open ${info.urls[info.urls.length - 1]?.replace(/\/$/, '') ?? ''}${CA_PAGE_PATH} ` +
          `(HTTPS only), install the CA it offers and trust it if it shows CA SHA-256 ${tls.ca.fingerprint}`,
      );
    if (info.redirectPort !== null)
      lines.push(`  plain HTTP on port ${info.redirectPort} redirects to HTTPS`);
    for (const n of tlsNotes) lines.push(`  note:     ${n}`);
  }
  lines.push(`  data:     ${dataDir}`);
  lines.push(`Open the console at:`, ...info.urls.map((u) => `  ➜ ${u}`));
  log.banner('listening', lines.join('\n'), {
    urls: info.urls,
    port: info.port,
    dist: distDir,
    machines: { file: machines.file, demo: machines.file === null, count: machines.machines.length },
    users,
    openOnNetwork,
    https: tls
      ? {
          source: tls.source,
          fingerprint: tls.fingerprint,
          certFile: tls.certFile,
          validTo: tls.validTo.toISOString(),
          ...(tls.ca ? { caFingerprint: tls.ca.fingerprint, caFile: tls.ca.file } : {}),
          notes: tlsNotes,
        }
      : null,
    redirectPort: info.redirectPort,
    dataDir,
  });
}
