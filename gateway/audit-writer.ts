import type { AuditEntry, AuditLog } from './audit';
import type { Logger } from './log';
import { REFUSAL_LIMIT, RefusalAggregator } from './refusals';
import type { AuditService, CommandAudit } from './services';

/**
 * The gateway's writers of the audit log (context.ts): entries, a command's entry written before
 * it is forwarded, the listeners of what is written, refusals limited per user or address.
 */
export function createAuditWriter(audit: AuditLog, log: Logger, now: () => number): AuditService {
  const nowIso = (): string => new Date(now()).toISOString();
  const append = (e: Omit<AuditEntry, 'time'> & { time?: string }): void => {
    try {
      audit.append({ ...e, time: e.time ?? nowIso() });
    } catch (err) {
      log.error('could not write the audit log', { error: String(err) });
    }
  };
  // Refusals (and attempts the login/PIN limiter refused) are limited per user, or per address
  // for clients without a session.
  const refusals = new RefusalAggregator(REFUSAL_LIMIT, now, append);
  const recordListeners = new Set<(e: Omit<AuditEntry, 'time'>) => void>();
  const record = (e: Omit<AuditEntry, 'time'>): void => {
    if (refusals.admit(e)) append(e);
    tell(e);
  };
  const beginCommand = (e: Omit<AuditEntry, 'time' | 'result' | 'type'>): CommandAudit | null => {
    let begun: { entry: AuditEntry; id: number };
    try {
      begun = audit.begin({ ...e, type: 'command', time: nowIso() });
    } catch (err) {
      log.error('a command was refused: its audit entry cannot be written', {
        machine: e.machine,
        user: e.user,
        label: e.label,
        error: String(err),
      });
      return null;
    }
    let finished = false;
    return {
      done(r) {
        if (finished) return;
        finished = true;
        const ok = r.status !== undefined && r.status < 400 && r.error === undefined;
        const entry: AuditEntry = { ...begun.entry, result: ok ? 'ok' : 'error', ...r };
        try {
          audit.finish(begun.id, entry);
        } catch (err) {
          log.error('could not write the outcome of a command to the audit log', {
            machine: e.machine,
            error: String(err),
          });
        }
        const { time: _time, ...rest } = entry;
        tell(rest);
      },
    };
  };
  const tell = (e: Omit<AuditEntry, 'time'>): void => {
    for (const l of recordListeners) {
      try {
        l(e);
      } catch (err) {
        log.error('a listener of the audit records failed', { error: String(err) });
      }
    }
  };
  const onRecord = (listener: (e: Omit<AuditEntry, 'time'>) => void): (() => void) => {
    recordListeners.add(listener);
    return () => recordListeners.delete(listener);
  };
  return { audit, record, beginCommand, onRecord, refusals };
}
