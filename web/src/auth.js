// The page's API key. A server started with `amc serve --auth-keys FILE`
// wants `Authorization: Bearer KEY` on every API call (the page's own files
// and /healthz stay public); one started without keys never answers 401, so
// the page never asks. Every call the page makes to the API goes through
// `authFetch`: it sends the key when one is stored, asks for one in the
// page's dialog on a 401 and tries again with it (a key the server refuses:
// the dialog says so and asks again, until Cancel), and turns a 403 (the key
// lacks a role) and a 429 (too many requests or failed keys) into errors that
// say what to do. The key lives in sessionStorage: this tab only, gone when
// it closes; never localStorage, never a URL (the live feed's WebSocket gets
// a one-use ticket instead, live.js).
import { $ } from './state.js';

const STORE = 'amc-api-key';

/** An API call refused for its key (401: none given; 403: a role missing) or its rate (429). */
export class ApiError extends Error {
  constructor(message, status, retryAfter = null) {
    super(message);
    this.status = status;
    /** Seconds the server asks to wait (429), or null. */
    this.retryAfter = retryAfter;
  }
}

/** The stored key, or null. */
export function storedKey() {
  try { return sessionStorage.getItem(STORE) || null; } catch { return null; }
}

function storeKey(key) {
  try { sessionStorage.setItem(STORE, key); } catch { /* storage off: the key lives until the page is left */ }
  memoryKey = key;
  showForget();
}

/** Forgets the stored key (the "Forget API key" button); the next call that needs one asks again. */
export function forgetKey() {
  try { sessionStorage.removeItem(STORE); } catch { /* nothing stored */ }
  memoryKey = null;
  showForget();
}

// Where sessionStorage is off (some privacy settings), the key is kept in this module only.
let memoryKey = null;
const currentKey = () => storedKey() || memoryKey;

function showForget() {
  const b = $('forget-key');
  if (b) b.hidden = !currentKey();
}

/** The problem+json's `detail` (or `title`), else null. */
export async function problemDetail(res) {
  try { const p = await res.clone().json(); return p.detail || p.title || null; } catch { return null; }
}

const sameOrigin = (url) => { try { return new URL(url, location.href).origin === location.origin; } catch { return false; } };

/** `init` with the key's header; a key goes only to this page's own server. */
function withKey(url, init, key) {
  if (!key || !sameOrigin(url)) return init;
  const headers = new Headers(init.headers || undefined);
  headers.set('Authorization', `Bearer ${key}`);
  return { ...init, headers };
}

// Whether a bodiless probe has shown that this server wants no key.
let openServer = false;

/**
 * `fetch` with the page's key. `init.what` names the action for a 403's message
 * ("submit jobs"), `init.role` the role it needs when the server's detail names
 * none. Resolves to the response (any status but 401, 403 and 429); rejects
 * with an `ApiError` for those (401: no key given).
 */
export async function authFetch(url, init = {}) {
  const { what = 'do this', role = null, ...req } = init;
  // An upload without a key: ask a cheap question first, so a large clip is not
  // sent only to be refused (and a server that answers before reading it all
  // cannot reset the upload under the browser).
  if (req.body && !currentKey() && !openServer && sameOrigin(url)) {
    const probe = await authFetch('/openapi.json', { method: 'HEAD', what });
    if (probe.ok) openServer = true;
  }
  let sent = currentKey();
  let res = await fetch(url, withKey(url, req, sent));
  while (res.status === 401 && sameOrigin(url)) {
    const now = currentKey();
    if (now && now !== sent) {
      sent = now; // another call got a key while this one waited: try it
    } else {
      if (sent) forgetKey();
      const key = await askKey(sent ? 'The server did not accept this key. Try another (or ask its operator).' : null);
      if (!key) throw new ApiError('this server needs an API key, and none was given (ask its operator; `amc keys new`)', 401);
      storeKey(key);
      sent = key;
    }
    res = await fetch(url, withKey(url, req, sent));
  }
  if (res.status === 403) throw new ApiError(forbidden(what, role, await problemDetail(res)), 403);
  if (res.status === 429) {
    const secs = retryAfter(res);
    throw new ApiError(`too many requests, retry in ${secs} s`, 429, secs);
  }
  return res;
}

/** Seconds from `Retry-After` (seconds or an HTTP date); 1 when missing. */
function retryAfter(res) {
  const h = res.headers.get('Retry-After');
  if (h && /^\d+$/.test(h.trim())) return Number(h.trim());
  const t = h ? Date.parse(h) : NaN;
  return Number.isFinite(t) ? Math.max(1, Math.ceil((t - Date.now()) / 1000)) : 1;
}

/**
 * "this key may not submit jobs (role submit or admin missing)": the role the
 * server's detail says is needed ("… it needs the role submit (or admin)"),
 * else the server's detail as it is, else the role the action needs.
 */
export function forbidden(what, role, detail) {
  const roles = '([a-z]+(?:\\s*(?:,|\\(?or\\b)\\s*[a-z]+\\)?)*)';
  const m = detail && (detail.match(new RegExp(`\\bneeds?\\s+(?:the\\s+)?roles?\\s+[\`"']?${roles}`, 'i')) ||
    detail.match(new RegExp(`\\broles?\\s+[\`"']?${roles}[\`"']?\\s+(?:is\\s+)?missing`, 'i')));
  if (m) return `this key may not ${what} (role ${m[1].replace(/\(or\s+([a-z]+)\)/gi, 'or $1')} missing)`;
  if (detail) return `this key may not ${what}: ${detail}`;
  return `this key may not ${what}${role ? ` (role ${role} missing)` : ''}`;
}

// --- The key dialog -----------------------------------------------------------

let asking = null;

/** Asks for a key in the page's dialog; resolves to it, or null on Cancel. One dialog for all the calls that wait. */
function askKey(note) {
  if (asking) return asking;
  const dlg = $('key-dialog'), form = $('key-form'), input = $('key-input'), err = $('key-error');
  asking = new Promise((resolve) => {
    err.textContent = note || '';
    err.hidden = !note;
    input.value = '';
    const done = (key) => {
      form.onsubmit = null; $('key-cancel').onclick = null; dlg.oncancel = null;
      if (dlg.open) dlg.close();
      input.value = '';
      asking = null;
      resolve(key);
    };
    form.onsubmit = (e) => {
      e.preventDefault();
      const key = input.value.trim();
      if (key) done(key); else input.focus();
    };
    $('key-cancel').onclick = () => done(null);
    dlg.oncancel = (e) => { e.preventDefault(); done(null); }; // Escape
    dlg.showModal();
    input.focus();
  });
  return asking;
}

/** Wires the "Forget API key" button. */
export function initAuth() {
  $('forget-key').onclick = () => { forgetKey(); $('forget-key').blur(); };
  showForget();
}
