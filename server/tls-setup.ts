import type https from 'node:https';
import path from 'node:path';
import type { Logger } from './log';
import { ensureSelfSigned, filesStamp, loadTlsFiles, TlsSetupError, type TlsMaterial } from './tls-cert';

/**
 * The server's HTTPS setting and certificate: the owner's files (`SHOPDECK_TLS_CERT`/`_KEY`) or a
 * kept self-signed one (`SHOPDECK_HTTPS=1`, tls-cert.ts), reloaded when renewed or expired.
 */

export type HttpsSetting = 'off' | 'self-signed' | { certFile: string; keyFile: string };

export function httpsFromEnv(env: NodeJS.ProcessEnv, cwd: string): HttpsSetting {
  const cert = env.SHOPDECK_TLS_CERT;
  const key = env.SHOPDECK_TLS_KEY;
  if (cert || key) {
    if (!cert || !key)
      throw new TlsSetupError('set both SHOPDECK_TLS_CERT and SHOPDECK_TLS_KEY (PEM files), or neither');
    return { certFile: path.resolve(cwd, cert), keyFile: path.resolve(cwd, key) };
  }
  const flag = (env.SHOPDECK_HTTPS ?? '').toLowerCase();
  return flag === '1' || flag === 'true' || flag === 'yes' ? 'self-signed' : 'off';
}

export class ServerTls {
  /** null: plain HTTP. */
  current: TlsMaterial | null;
  /** What the owner should know of the certificate (the start banner). */
  readonly notes: string[] = [];
  private stamp: string;

  constructor(
    private readonly setting: HttpsSetting,
    private readonly dataDir: string,
    /** The names a self-signed certificate is made for. */
    private readonly wantedNames: () => string[],
  ) {
    this.current = this.load();
    this.stamp = this.current ? filesStamp(this.current.certFile, this.current.keyFile) : '';
  }

  private load(): TlsMaterial | null {
    const setting = this.setting;
    if (setting === 'off') return null;
    if (setting === 'self-signed') {
      const r = ensureSelfSigned(this.dataDir, this.wantedNames());
      if (r.made === 'the kept certificate expired')
        this.notes.push(
          'the kept certificate had expired: a new one was made, tablets must trust its CA again',
        );
      if (r.missing.length)
        this.notes.push(
          `the certificate does not name ${r.missing.join(', ')}: browsers warn there. To add them, set SHOPDECK_TLS_NAMES ` +
            `if needed and delete ${path.dirname(r.material.certFile)} (a new certificate is made; tablets must trust it again)`,
        );
      return r.material;
    }
    return loadTlsFiles(setting.certFile, setting.keyFile);
  }

  /**
   * Renewed certificates (Let's Encrypt, a replaced file) and an expired self-signed one (the
   * server checks hourly): a changed certificate goes to `server`; one that cannot be loaded is
   * logged and the current one kept.
   */
  refresh(server: https.Server, log: Logger): void {
    const tls = this.current;
    if (!tls) return;
    try {
      const expired = tls.validTo.getTime() <= Date.now();
      const stamp = filesStamp(tls.certFile, tls.keyFile);
      if (stamp === this.stamp && !expired) return;
      const next = this.load();
      if (!next) return;
      this.stamp = filesStamp(next.certFile, next.keyFile);
      if (next.fingerprint === tls.fingerprint) return;
      server.setSecureContext({ key: next.key, cert: next.cert });
      this.current = next;
      log.warn('new HTTPS certificate', { fingerprint: next.fingerprint, ca: next.ca?.fingerprint });
    } catch (e) {
      log.error('cannot reload the HTTPS certificate: keeping the current one', {
        error: e instanceof Error ? e.message : String(e),
      });
    }
  }
}
