import { defaultDecision, type AccessDecision, type AccessRequest } from '../src/fleet/access';
import { roleAtLeast } from '../src/fleet/types';
import type { MachineEntry } from './machines';
import type { Families } from './options';
import { mayUseMachine } from './identity';
import type { MachineHints, MachinesService, Verdict, Who } from './services';

/**
 * Per machine (context.ts): its family's hints (held session, sharing), the access decision of a
 * request (the family's rule; a rule that throws makes it supervisor only) and the verdict on who
 * asks (401 no session, 403 another's machine or a lower role).
 */
export function createMachineAccess(
  families: Families,
): Pick<MachinesService, 'hintsOf' | 'classify' | 'authorize'> {
  const hints = new Map<string, MachineHints>();
  function hintsOf(m: MachineEntry): MachineHints {
    let h = hints.get(m.id);
    if (!h) {
      const g = families[m.kind]?.gateway;
      h = g?.forMachine
        ? g.forMachine({ id: m.id, ...(m.api ? { api: m.api } : {}) })
        : { session: g?.session, sharing: g?.sharing };
      hints.set(m.id, h);
    }
    return h;
  }

  function classify(m: MachineEntry, req: AccessRequest): AccessDecision {
    const fam = families[m.kind];
    if (!fam) return defaultDecision(req);
    try {
      return fam.access(req);
    } catch (e) {
      return {
        role: 'supervisor',
        command: true,
        label: `${req.method} ${req.path} (the access rule failed: supervisor only; ${e instanceof Error ? e.message : String(e)})`,
      };
    }
  }

  function authorize(w: Who, m: MachineEntry, d: AccessDecision): Verdict {
    if (!w.principal) {
      return {
        ok: false,
        status: 401,
        body: {
          error: w.expired ? 'your session expired: log in again' : 'log in first',
          needs: d.role,
          login: true,
        },
      };
    }
    const p = w.principal;
    if (!mayUseMachine(p, m.id)) {
      return {
        ok: false,
        status: 403,
        body: { error: `${p.name} may not use the machine ${m.id}`, needs: d.role },
      };
    }
    if (!roleAtLeast(p.role, d.role)) {
      return {
        ok: false,
        status: 403,
        body: { error: `${d.label}: needs the ${d.role} role (${p.name} is ${p.role})`, needs: d.role },
      };
    }
    return { ok: true, principal: p };
  }

  return { hintsOf, classify, authorize };
}
